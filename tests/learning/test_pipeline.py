"""The pipeline's learning stages: `tomstudy train` and the family training of a bundle build
give identical checkpoints; `tomstudy sweep` and `tomstudy select`."""

import json
import shutil

import pytest
import yaml
from typer.testing import CliRunner

from app.cli import cli
from app.core.files import write_json
from app.layout import Layout
from app.learning.checkpoint import load_model
from app.learning.config import TrainConfig
from app.learning.family import train_family
from app.settings import get_settings
from tests.learning.synthetic import make_lane_trajs

TINY = {"max_epochs": 2, "patience_epochs": 1, "windows_per_trajectory": 4,
        "encoder_hidden": [16], "decoder_hidden": [16]}


@pytest.fixture
def data_dir(tmp_path, monkeypatch):
    """A data dir holding one small simulated world ("lanes"), and settings pointing at it."""
    layout = Layout(tmp_path / "var")
    trajs = make_lane_trajs(60, seed=1)
    trajs.save(layout.trajectories("lanes"))
    write_json(layout.trajectories_meta("lanes"), {"world": "lanes", "seed": 1, "n": 60})
    configs = tmp_path / "configs"
    configs.mkdir()
    (configs / "training.yaml").write_text(yaml.safe_dump(TINY))
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(layout.root))
    monkeypatch.setenv("TOMSTUDY_CONFIGS_DIR", str(configs))
    get_settings.cache_clear()
    yield layout
    get_settings.cache_clear()


def cli_train(model_name: str, seed: int = 0) -> None:
    """`tomstudy train --world lanes --model <model_name> --seed <seed>` with the tiny
    training.yaml."""
    config = get_settings().configs_dir / "training.yaml"
    result = CliRunner().invoke(cli, ["train", "--world", "lanes", "--model", model_name,
                                      "--seed", str(seed), "--config", str(config)])
    assert result.exit_code == 0, result.output


def test_train_and_the_family_build_write_the_same_checkpoints(data_dir, tmp_path):
    for seed in (0, 1):
        for model_name in ("ours", "vae"):
            cli_train(model_name, seed)
    moved = Layout(tmp_path / "elsewhere")  # the bundle build's step, in a copy of the data dir
    shutil.copytree(data_dir.world_data("lanes"), moved.world_data("lanes"))
    said = []
    ran = train_family(moved, ["lanes"], [0, 1], TrainConfig(**TINY), workers=2, say=said.append)
    assert sorted(ran) == [("lanes", m, s) for m in ("ours", "vae") for s in (0, 1)]
    for seed in (0, 1):
        for model_name in ("ours", "vae"):
            by_cli = load_model(data_dir.checkpoint("lanes", model_name, seed))
            by_family = load_model(moved.checkpoint("lanes", model_name, seed))
            assert by_cli.content_hash == by_family.content_hash
            assert by_cli.data_meta["source"] == {"world": "lanes", "seed": 1, "n": 60}
        vae = load_model(data_dir.checkpoint("lanes", "vae", seed))
        ours = load_model(data_dir.checkpoint("lanes", "ours", seed))
        assert len(vae.kmeans_centres) == ours.codes["n_codes_used"]
    seeds = {load_model(data_dir.checkpoint("lanes", "ours", s)).content_hash for s in (0, 1)}
    assert len(seeds) == 2  # two seeds, two networks
    assert train_family(moved, ["lanes"], [0, 1], TrainConfig(**TINY), say=said.append) == []
    assert said[-2:] == [f"training 0 {m} checkpoint(s) on 2 process(es); 2 already exist"
                         for m in ("ours", "vae")]


def test_the_vae_without_an_ours_checkpoint_is_a_clear_error(data_dir):
    result = CliRunner().invoke(cli, ["train", "--world", "lanes", "--model", "vae"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "no Ours checkpoint" in result.output and "--ours-checkpoint" in result.output
    assert not data_dir.checkpoint("lanes", "vae").exists()


def test_sweep_is_a_tomstudy_command(data_dir, monkeypatch):
    monkeypatch.setattr("app.learning.sweep.SETTINGS", [{"levels": [3, 3]}])
    result = CliRunner().invoke(cli, ["sweep", "--world", "lanes"])
    assert result.exit_code == 0, result.output
    assert '{"levels": [3, 3]}' in result.output and "purity/NMI" in result.output
    rows = (data_dir.sweep_dir("lanes") / "sweep.jsonl").read_text().splitlines()
    assert [json.loads(row)["settings"] for row in rows] == [{"levels": [3, 3]}]
    result = CliRunner().invoke(cli, ["sweep", "--world", "highway"])
    assert result.exit_code == 2 and "run `tomstudy simulate highway` first" in result.output


def test_select_is_a_tomstudy_command(data_dir, tmp_path):
    grids = tmp_path / "selection.yaml"
    grids.write_text("vae: {beta_kl: [0.01], latent_dim: [2]}\nours: {levels: [[2, 2]]}\n")
    result = CliRunner().invoke(cli, ["select", "--world", "lanes", "--config", str(grids)])
    assert result.exit_code == 0, result.output
    assert "put this under `selected:`" in result.output and "  lanes:" in result.output
    saved = json.loads((data_dir.selection_dir("lanes") / "selection.json").read_text())
    assert saved["chosen"]["ours"] == {"levels": [2, 2]}
