"""An export written before export_version 2 (human_vx, click_x, no export_version) reads and
analyses as the current one; an export newer than the code is refused."""

import io

import pandas as pd
import pytest

from analysis.exports import read_export
from analysis.load import DataError, load_csv
from analysis.report import run_analyze
from app.core.contracts import EXPORT_VERSION, RENAMED_COLUMNS, SURVEY
from tests.analysis.fixed_data import fixed_predictions
from tests.analysis.report_inputs import simulated_export

OLD_NAMES = {new: old for old, new in RENAMED_COLUMNS.items()}


def as_version_1(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows as an export before export_version wrote them: old names, no version column."""
    return frame.drop(columns="export_version").rename(columns=OLD_NAMES)


def test_a_version_1_export_reads_under_the_new_names(tmp_path):
    frame = fixed_predictions()
    old = as_version_1(frame)
    assert {"human_vx", "click_x", "human_x"} <= set(old.columns)
    old.to_csv(tmp_path / "old.csv", index=False)
    back = load_csv(tmp_path / "old.csv")
    assert (back["export_version"] == 1).all() and (frame["export_version"] == 2).all()
    assert back.drop(columns="export_version").equals(frame.drop(columns="export_version"))
    assert list(back.columns) == list(frame.columns)


def test_a_version_1_export_analyses_as_the_current_one(tmp_path, inputs):
    frame = simulated_export("coarse", 8, seed=4)
    frame.to_csv(tmp_path / "new.csv", index=False)
    as_version_1(frame).to_csv(tmp_path / "old.csv", index=False)
    new = run_analyze("paper_study", tmp_path / "new", tmp_path / "new.csv", "", inputs)
    old = run_analyze("paper_study", tmp_path / "old", tmp_path / "old.csv", "", inputs)
    assert old["ours_vs_vae"] == new["ours_vs_vae"] and old["worlds"] == new["worlds"]
    assert old["zero_vectors"] == new["zero_vectors"]
    for name in ("per_participant.csv", "by_start_kind.csv", "ceiling.csv"):
        assert (tmp_path / "old" / name).read_text() == (tmp_path / "new" / name).read_text()


def test_an_export_newer_than_the_code_is_refused(tmp_path):
    frame = fixed_predictions().assign(export_version=EXPORT_VERSION + 1)
    frame.to_csv(tmp_path / "newer.csv", index=False)
    with pytest.raises(DataError, match="export_version: 3 is newer"):
        load_csv(tmp_path / "newer.csv")


def test_the_other_exports_without_export_version_read_as_version_1():
    row = {c: "" for c in SURVEY if c != "export_version"} | {"answered_at": "2026-01-01T00:00Z"}
    text = pd.DataFrame([row]).to_csv(index=False)
    assert read_export(io.StringIO(text), "survey")["export_version"].tolist() == [1]
