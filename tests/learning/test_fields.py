"""Vector fields: one per used code, JSON-able, and PNGs over the scene."""

import json

import numpy as np
from typer.testing import CliRunner

from app.cli import cli
from app.learning.checkpoint import load_model
from app.learning.fields import vector_field, write_fields
from tests.learning.synthetic import lane_scene


def test_vector_field_has_one_entry_per_used_code(trained):
    model = load_model(trained["ours"])
    field = vector_field(model, lane_scene(0.5), [20.0, 4.0], grid_n=6)
    assert len(field["xs"]) == 6 and len(field["ys"]) == 6
    assert [c["code"] for c in field["codes"]] == [c["code"] for c in model.codes["used"]]
    for entry in field["codes"]:
        assert np.asarray(entry["actions"]).shape == (36, 2)
    json.dumps(field)


def test_write_fields_draws_every_code_of_both_models(trained, tmp_path):
    for model_name in ("ours", "vae"):
        paths = write_fields(trained[model_name], tmp_path / model_name, grid_n=5)
        pngs = [p for p in paths if p.suffix == ".png"]
        assert len(pngs) == load_model(trained[model_name]).codes["n_codes_used"] >= 1
        assert all(p.stat().st_size > 1000 for p in pngs)
        saved = json.loads((tmp_path / model_name / "fields.json").read_text())
        assert saved["kind"] == model_name and len(saved["codes"]) == len(pngs)


def test_cli_fields_and_train_give_clean_errors(tmp_path, monkeypatch):
    from app.settings import get_settings

    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"nope")
    result = CliRunner().invoke(cli, ["fields", "--checkpoint", str(bad)])
    assert result.exit_code == 2 and "not a readable checkpoint" in result.output
    assert "Traceback" not in result.output
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(tmp_path))
    get_settings.cache_clear()
    try:
        result = CliRunner().invoke(cli, ["train", "--world", "highway", "--model", "ours"])
        assert result.exit_code == 2 and "run `tomstudy simulate highway` first" in result.output
        result = CliRunner().invoke(cli, ["train", "--world", "highway", "--model", "gan"])
        assert result.exit_code == 2 and "unknown model" in result.output
    finally:
        get_settings.cache_clear()


def test_code_summaries_name_the_robot_label_first(trained):
    from app.learning.fields import primary_label

    model = load_model(trained["ours"])
    majority = model.codes["used"][0]["majority"]
    assert {"robot_intent", "robot_intent_in_progress"} <= set(majority)
    assert majority["robot_intent"]["label"] in ("keep", "left", "right")
    assert primary_label(majority) == "robot_intent"
    assert primary_label(["robot_goal_before_arrival", "human_goal", "robot_goal"]) == "robot_goal"
