"""`analyze` writes a self-contained report whose numbers match the per-participant table."""

import json

import numpy as np
import pandas as pd
import pytest

from analysis.contracts import ExclusionRules
from analysis.metrics import add_alignment_errors
from analysis.report import AnalysisError, StudyInputs, run_analyze, start_kind_table
from app.observers.simulated_study import simulate_participants
from tests.analysis.fixed_data import fixed_predictions, small_bank

RULES = ExclusionRules(failed_attention_check=True, incomplete=True, too_fast_trial_ms=4000,
                       too_fast_max_fraction=0.25)


@pytest.fixture
def inputs(tmp_path) -> StudyInputs:
    """The study's side of an analysis: a bank on disk, one absent checkpoint."""
    bank = tmp_path / "var" / "trials" / "paper_study" / "bank.json"
    bank.parent.mkdir(parents=True)
    bank.write_text(json.dumps(small_bank()))
    config = {"exclusions": RULES.model_dump(), "models": {"highway": {"ours": "ours.pt"}}}
    return StudyInputs(config=config, rules=RULES, bank=bank,
                       checkpoints={"highway/ours": tmp_path / "var" / "ours.pt"})


def test_report_from_csv(tmp_path, inputs):
    frame = simulate_participants(small_bank(), "coarse", 12, 5, seed=3, show_progress=False)
    frame.loc[frame["participant_id"] == "sim-00001", "completed"] = False
    frame.to_csv(tmp_path / "export.csv", index=False)
    out = tmp_path / "report"
    summary = run_analyze("paper_study", out, tmp_path / "export.csv", "", inputs)
    for name in ("report.html", "summary.json", "per_participant.csv", "meta.json",
                 "alignment_error.png", "alignment_error.svg", "fields_highway.png",
                 "fields_obstacle.svg"):
        assert (out / name).is_file(), name
    assert summary["exclusions"]["excluded_incomplete"] == 1
    table = pd.read_csv(out / "per_participant.csv")
    assert table["participant_id"].nunique() == 11
    for world, res in summary["ours_vs_vae"].items():
        rows = table[table["world"] == world]
        assert res["n"] == len(rows) == 11
        assert res["mean_a"] == pytest.approx(rows["err_ours"].mean())
        assert summary["worlds"][world]["err_vae"]["mean"] == pytest.approx(rows["err_vae"].mean())
    html = (out / "report.html").read_text()
    assert "data:image/png;base64," in html and "src='http" not in html
    meta = json.loads((out / "meta.json").read_text())
    assert len(meta["data_sha256"]) == 64 and meta["trial_bank_sha256"]
    assert meta["checkpoint_sha256"] == {"highway/ours": None}
    assert meta["study_config"] == inputs.config

    assert "start_kind" in pd.read_csv(tmp_path / "export.csv").columns
    kinds = pd.read_csv(out / "by_start_kind.csv")
    assert list(kinds.columns[:3]) == ["world", "start_kind", "n"]
    assert list(kinds[kinds["world"] == "highway"]["start_kind"]) == [
        "own", "same_lane", "adjacent_lane"]
    assert list(kinds[kinds["world"] == "obstacle"]["start_kind"]) == ["own", "near", "mid"]
    assert (kinds["n"] == 11).all()
    kept = add_alignment_errors(frame[frame["participant_id"] != "sim-00001"])
    for row in kinds.itertuples():
        rows = kept[(kept["world"] == row.world) & (kept["start_kind"] == row.start_kind)]
        per_person = rows.groupby("participant_id")[["err_ours", "err_vae"]].mean()
        assert row.err_ours == pytest.approx(per_person["err_ours"].mean())
        assert row.mean_diff == pytest.approx((per_person["err_ours"]
                                               - per_person["err_vae"]).mean())
        assert summary["by_start_kind"][row.world][row.start_kind]["n"] == 11
    assert "adjacent_lane" in html and "By start kind" in html


def test_start_kind_table_with_one_participant_has_no_test():
    rows = add_alignment_errors(fixed_predictions(n_participants=3, starts=2))
    rows = rows[(rows["start_kind"] == "own") | (rows["participant_id"] == "p00")]
    table = start_kind_table(rows).set_index(["world", "start_kind"])
    assert table.loc[("highway", "own"), "n"] == 3
    assert np.isfinite(table.loc[("highway", "own"), "t"])
    one = table.loc[("highway", "same_lane")]
    assert one["n"] == 1 and np.isnan(one["t"]) and np.isfinite(one["mean_diff"])


def test_all_excluded_is_a_clear_error_and_waive_is_reported(tmp_path, inputs):
    frame = simulate_participants(small_bank(), "random", 6, 5, seed=4, show_progress=False)
    frame["attention_passed"] = False
    frame.to_csv(tmp_path / "export.csv", index=False)
    with pytest.raises(AnalysisError, match="every participant was excluded"):
        run_analyze("paper_study", tmp_path / "r1", tmp_path / "export.csv", "", inputs)
    summary = run_analyze("paper_study", tmp_path / "r2", tmp_path / "export.csv", "", inputs,
                          waive=("failed_attention_check",))
    assert summary["waived_rules"] == ["failed_attention_check"]
    assert summary["exclusions"]["participants_kept"] == 6
    with pytest.raises(AnalysisError, match="waive: unknown"):
        run_analyze("paper_study", tmp_path / "r3", tmp_path / "export.csv", "", inputs,
                    waive=("attention",))
