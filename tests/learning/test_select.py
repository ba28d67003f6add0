"""Model selection: VAE latent size, per-world selected values, rules, outputs."""

import json

import pytest
import torch
import yaml

from app.configio import ConfigError
from app.learning.checkpoint import CheckpointError, load_model, save_checkpoint
from app.learning.config import TrainConfig
from app.learning.models import build_model, model_args
from app.learning.select import (
    OursGrid,
    SelectionConfig,
    VaeGrid,
    choose_ours,
    load_selection_config,
    markdown,
    run_selection,
    task_loss,
    write_outputs,
    yaml_lines,
)
from app.learning.train import prepare, train_and_save
from tests.learning.synthetic import make_lane_trajs

TINY = TrainConfig(max_epochs=2, patience_epochs=1, windows_per_trajectory=4,
                   encoder_hidden=[16], decoder_hidden=[16])


@pytest.fixture(scope="module")
def tiny_trajs():
    """60 analytic lane trajectories."""
    return make_lane_trajs(60, seed=1)


def test_vae_latent_size_is_independent_of_levels():
    cfg = TrainConfig(levels=[3, 3, 3], vae_latent_dim=4)
    assert cfg.latent_dim("ours") == 3 and cfg.latent_dim("vae") == 4
    vae = build_model("vae", model_args(cfg, "vae"))
    ours = build_model("ours", model_args(cfg, "ours"))
    assert vae.latent_dim == 4 and vae.decoder[0].in_features == 4 + 4
    assert ours.latent_dim == 3


def test_train_model_applies_only_its_worlds_selection(tiny_trajs, tmp_path):
    cfg = TrainConfig.model_validate({**TINY.model_dump(), "selected": {
        "lanes": {"vae_latent_dim": 4, "beta_kl": 0.5}, "elsewhere": {"vae_latent_dim": 3}}})
    model = load_model(train_and_save(tiny_trajs, "vae", 0, cfg, tmp_path, progress=False,
                                      vae_clusters=2))
    assert model.latent_dim == 4 and model.encode(tiny_trajs.positions[0, :6]).shape == (4,)
    assert model.train_config["beta_kl"] == 0.5 and model.train_config["selected"] == {}
    assert model.train_config["levels"] == [3, 3]  # no `levels` chosen: the default stays


def test_old_checkpoints_load_and_an_inconsistent_latent_size_is_named(trained, tmp_path):
    raw = torch.load(trained["vae"], weights_only=True)
    old = {k: v for k, v in raw.items() if k not in ("format", "content_hash")}
    old["train_config"] = {k: v for k, v in old["train_config"].items()
                           if k not in ("vae_latent_dim", "selected")}
    save_checkpoint(tmp_path / "old.pt", old)
    assert load_model(tmp_path / "old.pt").latent_dim == 2
    bad = dict(old, model_args={**old["model_args"], "latent_dim": 4})
    save_checkpoint(tmp_path / "bad.pt", bad)
    with pytest.raises(CheckpointError, match="latent_dim 4"):
        load_model(tmp_path / "bad.pt")


def test_the_kl_term_is_not_part_of_the_criterion(tiny_trajs):
    data = prepare(tiny_trajs, TINY)
    torch.manual_seed(0)
    small = build_model("vae", model_args(TINY.model_copy(update={"beta_kl": 0.01}), "vae"))
    large = build_model("vae", model_args(TINY.model_copy(update={"beta_kl": 100.0}), "vae"))
    large.load_state_dict(small.state_dict())
    a, b = task_loss(small, data.val, TINY), task_loss(large, data.val, TINY)
    assert a["val_task_loss"] == pytest.approx(b["val_task_loss"])
    assert a["val_task_loss"] == pytest.approx(a["val_pred"] + a["val_recon"])
    assert a["val_kl"] == pytest.approx(b["val_kl"]) and a["val_kl"] > 0
    rows = torch.arange(len(data.val.x))
    batch = data.val.batch(rows, torch.zeros_like(rows))
    with torch.no_grad():
        assert float(large.eval().losses(batch, 1, 1)["total"]) > \
            float(small.eval().losses(batch, 1, 1)["total"]) + 1


def _row(loss: float, used: int, size: int) -> dict:
    return {"val_task_loss": loss, "codes_used": used, "codebook_size": size}


def test_ours_rule():
    grid = OursGrid(levels=[[2, 2]], min_used_fraction=0.5, loss_tolerance=0.05)
    rows = [_row(1.00, 9, 27),   # lowest loss, but under half its codebook is used
            _row(1.10, 8, 9),    # the lowest eligible loss: the tolerance is 1.10 * 1.05
            _row(1.15, 4, 4),    # within it, 4 codes
            _row(1.14, 4, 8),    # within it, 4 codes and a lower loss -> chosen
            _row(1.20, 3, 4)]    # fewest codes but outside the tolerance
    assert choose_ours(rows, grid) == (3, True)
    assert choose_ours(rows[:3], grid) == (2, True)
    assert choose_ours([_row(2.0, 1, 9), _row(1.5, 1, 8)], grid) == (1, False)


def test_selection_picks_the_argmin_on_validation_and_writes_its_outputs(tiny_trajs, tmp_path):
    sel = SelectionConfig(vae=VaeGrid(beta_kl=[0.01, 1.0], latent_dim=[2]),
                          ours=OursGrid(levels=[[2, 2]]))
    result = run_selection(tiny_trajs, TINY, sel)
    vae = [row for row in result["rows"] if row["model"] == "vae"]
    assert len(vae) == 2 and sum(row["chosen"] for row in vae) == 1
    best = min(vae, key=lambda row: row["val_task_loss"])
    assert best["chosen"] and result["chosen"]["vae"] == best["settings"]
    assert result["chosen"]["ours"] == {"levels": [2, 2]}
    assert result["sensitivity"]["settings"] == {"levels": [2, 2], "fsq_noise_fraction": 0.0}
    assert set(result["test_information_only"]) == {"default", "paper_quantiser"}
    write_outputs(result, tmp_path)
    saved = json.loads((tmp_path / "selection.json").read_text())
    assert saved["chosen"] == result["chosen"] and "**chosen**" in markdown(result)
    cells = result["rows"] + [result["sensitivity"]]
    assert all(1 <= row["epochs_run"] <= TINY.max_epochs
               and row["converged"] == (row["stopped_by"] == "patience") for row in cells)
    table = markdown(result)
    assert "| epochs | converged |" in table
    assert table.count(" | yes | ") + table.count(" | no: hit the cap | ") == len(cells)
    pasted = yaml.safe_load("selected:\n" + (tmp_path / "selected.yaml").read_text())
    applied = TrainConfig(**pasted).for_world("lanes")
    assert (applied.levels, applied.beta_kl) == ([2, 2], best["settings"]["beta_kl"])
    assert yaml_lines(result).startswith("  lanes:\n")


def test_two_workers_choose_what_one_chooses(tiny_trajs):
    sel = SelectionConfig(vae=VaeGrid(beta_kl=[0.01, 1.0], latent_dim=[2]),
                          ours=OursGrid(levels=[[2, 2], [3, 3]]))

    def without_times(result):
        return [{k: v for k, v in row.items() if k != "wall_s"} for row in result["rows"]]

    one, two = run_selection(tiny_trajs, TINY, sel, 1), run_selection(tiny_trajs, TINY, sel, 2)
    assert without_times(one) == without_times(two) and one["chosen"] == two["chosen"]


def test_the_stated_grid_is_the_issues():
    sel = load_selection_config()
    assert sel.vae.beta_kl == [0.01, 0.1, 0.33, 1.0] and sel.vae.latent_dim == [2, 4]
    assert [3, 3] in sel.ours.levels and sel.sensitivity_fsq_noise_fraction == 0.0


def test_a_misspelt_key_is_an_error_naming_it(tmp_path):
    path = tmp_path / "selection.yaml"
    path.write_text("vae: {beta_kl: [0.1], latent_dims: [2]}\nours: {levels: [[3, 3]]}\n")
    with pytest.raises(ConfigError, match="vae.latent_dims"):
        load_selection_config(path)
    with pytest.raises(ValueError, match="selected.highway.level"):
        TrainConfig(selected={"highway": {"level": [3, 3]}})
