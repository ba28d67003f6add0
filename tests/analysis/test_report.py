"""`analyze` writes a self-contained report whose numbers match the per-participant table."""

import json

import pandas as pd
import pytest

from analysis.power import simulate_participants
from analysis.report import run_analyze
from tests.analysis.fixed_data import small_bank

STUDY_YAML = """
exclusions: {failed_attention_check: true, incomplete: true, too_fast_trial_ms: 4000,
             too_fast_max_fraction: 0.25}
models:
  highway: {ours: models/highway/ours/checkpoint.pt, vae: models/highway/vae/checkpoint.pt}
"""


@pytest.fixture
def study_dirs(tmp_path):
    configs, data = tmp_path / "configs", tmp_path / "var"
    configs.mkdir()
    (configs / "paper_study.yaml").write_text(STUDY_YAML)
    bank = data / "trials" / "paper_study" / "bank.json"
    bank.parent.mkdir(parents=True)
    bank.write_text(json.dumps(small_bank()))
    return configs, data


def test_report_from_csv(tmp_path, study_dirs):
    configs, data = study_dirs
    frame = simulate_participants(small_bank(), "coarse", 12, 5, seed=3, show_progress=False)
    frame.loc[frame["participant_id"] == "sim-00001", "completed"] = False
    frame.to_csv(tmp_path / "export.csv", index=False)
    out = tmp_path / "report"
    summary = run_analyze("paper_study", out, tmp_path / "export.csv", "", configs, data)
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


def test_all_excluded_is_a_clear_error_and_waive_is_reported(tmp_path, study_dirs):
    from app.configio import ConfigError

    configs, data = study_dirs
    frame = simulate_participants(small_bank(), "random", 6, 5, seed=4, show_progress=False)
    frame["attention_passed"] = False
    frame.to_csv(tmp_path / "export.csv", index=False)
    with pytest.raises(ConfigError, match="every participant was excluded"):
        run_analyze("paper_study", tmp_path / "r1", tmp_path / "export.csv", "", configs, data)
    summary = run_analyze("paper_study", tmp_path / "r2", tmp_path / "export.csv", "", configs,
                          data, waive=("failed_attention_check",))
    assert summary["waived_rules"] == ["failed_attention_check"]
    assert summary["exclusions"]["participants_kept"] == 6
    with pytest.raises(ConfigError, match="waive: unknown"):
        run_analyze("paper_study", tmp_path / "r3", tmp_path / "export.csv", "", configs, data,
                    waive=("attention",))
