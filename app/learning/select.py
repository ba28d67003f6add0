"""Choose the VAE's beta_kl and latent size and Ours' FSQ levels on validation data only.

Run: tomstudy select --world highway [--config FILE] [--train-config FILE] [--out DIR]

The grids and rules are in study_configs/model_selection.yaml, fixed before any run. Every
grid cell trains on the train split of var/data/<world>/trajectories.npz (training.yaml's
values plus the cell's, its `selected:` section ignored, seed from the selection config) and
is scored on the validation split only (each cell trains until its validation loss converges
or max_epochs, app/learning/convergence.py; the report says which):
- criterion: validation task loss, pred_weight * L_pred + recon_weight * L_recon (normalised
  MSE as in training; L_recon averaged over every step t of the segment), in eval mode (the
  VAE's posterior mean, Ours' rounded codes), as the deployed models run. The KL term is
  left out because beta_kl scales it: with it, different betas would not be comparable;
- VAE: the lowest validation task loss;
- Ours: the rule in `choose_ours` (used-code share, then fewest used codes within a loss
  tolerance of the best).
No label, test window or study output enters the choice. After the choice, Ours at the
chosen levels is trained once more with the paper's quantiser (fsq_noise_fraction 0): a
sensitivity row, never chosen. For information only, the chosen Ours and that row are then
scored on the test split (purity against the robot's labels, prediction MSE).

Writes <out>/<world>/selection.json, selection.md and selected.yaml (default out:
var/models/selection) and prints the lines to paste under `selected:` in
study_configs/training.yaml, which `tomstudy train` then applies to that world.
"""

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from pydantic import Field

from app.configio import StrictModel, load_yaml_model
from app.core.files import atomic_path, trajectory_hash, write_json
from app.data.trajectory import TrajectorySet
from app.layout import Layout
from app.learning.checkpoint import model_from_payload
from app.learning.config import TrainConfig, WorldSelection, load_train_config
from app.learning.convergence import stopping_record
from app.learning.jobs import JobPool, job_pool
from app.learning.model_metrics import code_usage, evaluate
from app.learning.models import model_args
from app.learning.networks import LatentActionModel
from app.learning.train import (
    Prepared,
    SplitTensors,
    build_payload,
    fit_network,
    one_thread,
    prepare,
    simulated_trajectories,
)
from app.settings import get_settings

VAE_RULE = "lowest validation task loss (prediction + reconstruction MSE, no KL term)"


class VaeGrid(StrictModel):
    """VAE cells: every beta_kl x latent_dim pair."""

    # the KL weights tried (each cell trains one beta_kl x latent_dim pair)
    beta_kl: list[float] = Field(min_length=1)
    # the latent sizes tried
    latent_dim: list[int] = Field(min_length=1)


class OursGrid(StrictModel):
    """Ours cells (one per levels list) and the parameters of the selection rule."""

    # the FSQ levels lists tried, one cell each
    levels: list[list[int]] = Field(min_length=1)
    # a cell is eligible when its used codes are at least this share (0-1) of its codebook
    min_used_fraction: float = Field(0.5, ge=0, le=1)
    # relative (>= 0): among eligible cells this close to the lowest eligible validation loss, the
    # one with the fewest used codes wins
    loss_tolerance: float = Field(0.05, ge=0)


class SelectionConfig(StrictModel):
    """study_configs/model_selection.yaml."""

    # training seed (>= 0) of every grid cell
    seed: int = Field(0, ge=0)
    # the VAE's grid
    vae: VaeGrid
    # Ours' grid and its selection rule
    ours: OursGrid
    # fsq_noise_fraction (0-1) of the sensitivity row: the chosen Ours retrained with this
    # quantiser, reported, never chosen
    sensitivity_fsq_noise_fraction: float = Field(0.0, ge=0, le=1)


def load_selection_config(path: Path | None = None) -> SelectionConfig:
    """Read the selection YAML (default study_configs/model_selection.yaml); errors name keys."""
    return load_yaml_model(path or get_settings().configs_dir / "model_selection.yaml",
                           SelectionConfig)


def ours_rule(grid: OursGrid) -> str:
    """The Ours rule in words, with its parameters."""
    return (f"eligible: used codes >= {grid.min_used_fraction:g} x codebook size; among "
            f"eligible cells within {grid.loss_tolerance:.0%} of the lowest eligible validation "
            "task loss, the fewest used codes, ties by lower loss; none eligible: lowest loss")


def grid_cells(sel: SelectionConfig) -> list[tuple[str, dict]]:
    """(model_name, training-config values) of every cell, VAE first."""
    vae = [("vae", {"beta_kl": beta, "vae_latent_dim": dim})
           for dim in sel.vae.latent_dim for beta in sel.vae.beta_kl]
    return vae + [("ours", {"levels": levels}) for levels in sel.ours.levels]


@torch.no_grad()
def task_loss(model: LatentActionModel, data: SplitTensors, cfg: TrainConfig) -> dict:
    """Validation task loss in eval mode, reconstruction averaged over every step t; no KL."""
    model.eval()
    rows = torch.arange(len(data.x))
    recon = 0.0
    for t in range(cfg.segment_len):
        parts = model.losses(data.batch(rows, torch.full_like(rows, t)), cfg.pred_weight,
                             cfg.recon_weight)
        recon += float(parts["recon"]) / cfg.segment_len
    pred, reg = float(parts["pred"]), float(parts["reg"])
    beta = getattr(model, "beta_kl", 0.0)
    return {"val_task_loss": cfg.pred_weight * pred + cfg.recon_weight * recon,
            "val_pred": pred, "val_recon": recon, "val_kl": reg / beta if beta > 0 else None}


@torch.no_grad()
def val_code_usage(model: LatentActionModel, data: SplitTensors, min_share: float) -> dict:
    """Ours' FSQ codes on validation windows: codes used, codebook size, perplexity."""
    codes = model.fsq.codes_to_indices(model.infer_latent(data.x)).numpy()
    usage = code_usage(codes, min_share)
    return {"codes_used": usage["n_codes_used"], "codebook_size": model.fsq.codebook_size,
            "perplexity": usage["perplexity"]}


def cell_config(base: TrainConfig, values: dict) -> TrainConfig:
    """training.yaml's values with the cell's on top and no per-world selection."""
    return TrainConfig.model_validate({**base.model_dump(), **values, "selected": {}})


def score_cell(model_name: str, values: dict, base: TrainConfig, data: Prepared,
               seed: int) -> tuple[dict, LatentActionModel]:
    """Train one cell on the train split and score it on validation; (row, model)."""
    started = time.perf_counter()
    cfg = cell_config(base, values)
    model, _, history = fit_network(model_name, seed, cfg, data, progress=False)
    row = {"model": model_name, "settings": values, **task_loss(model, data.val, cfg),
           **stopping_record(history, cfg.patience_epochs),
           "wall_s": round(time.perf_counter() - started, 1)}
    if model_name == "ours":
        row.update(val_code_usage(model, data.val, cfg.min_code_share))
    return row, model


def lowest_loss(rows: list[dict]) -> int:
    """Index of the row with the lowest validation task loss (the VAE rule)."""
    return int(np.argmin([row["val_task_loss"] for row in rows]))


def is_eligible(row: dict, grid: OursGrid) -> bool:
    """Whether an Ours cell uses enough of its codebook to be chosen."""
    return row["codes_used"] >= grid.min_used_fraction * row["codebook_size"]


def choose_ours(rows: list[dict], grid: OursGrid) -> tuple[int, bool]:
    """(index chosen by the rule in `ours_rule`, whether any cell was eligible)."""
    eligible = [i for i, row in enumerate(rows) if is_eligible(row, grid)]
    if not eligible:
        return lowest_loss(rows), False
    best = min(rows[i]["val_task_loss"] for i in eligible)
    near = [i for i in eligible if rows[i]["val_task_loss"] <= best * (1 + grid.loss_tolerance)]
    return min(near, key=lambda i: (rows[i]["codes_used"], rows[i]["val_task_loss"])), True


def held_out_information(trajs: TrajectorySet, seed: int, cfg: TrainConfig,
                         model: LatentActionModel, data: Prepared) -> dict:
    """Ours' held-out test purity (robot labels) and MSE: reported, never used to choose."""
    payload = build_payload(trajs, "ours", seed, cfg, model, model_args(cfg, "ours"), data)
    scores = evaluate(model_from_payload(payload), data.windows["test"], trajs.label_names,
                      cfg.min_code_share)
    return {"test_purity": {name: round(v["purity"], 3)
                            for name, v in scores["agreement"].items()
                            if name.startswith("robot_")},
            "test_mse": scores["prediction"]["mse"]}


def run_selection(trajs: TrajectorySet, base: TrainConfig, sel: SelectionConfig,
                  workers: int | JobPool = 1) -> dict:
    """Train and score every cell (`workers` at a time), apply the rules, add the sensitivity
    row; JSON-able dict. The result does not depend on `workers`: every cell trains on one
    thread from its seed."""
    started = time.perf_counter()
    base = cell_config(base, {})
    cells = grid_cells(sel)
    with job_pool(workers) as pool, one_thread():
        data = prepare(trajs, base)
        scored = pool.run(score_cell, [(m, v, base, data, sel.seed) for m, v in cells],
                          f"select {trajs.world}", "cell")
        rows, models = [row for row, _ in scored], [model for _, model in scored]
        result = _choose(rows, sel)
        chosen = result["chosen"]["ours"]
        default = models[next(i for i, row in enumerate(rows)
                              if row["model"] == "ours" and row["chosen"])]
        # the sensitivity row: chosen levels, the paper's quantiser; scored, never chosen
        paper = {**chosen, "fsq_noise_fraction": sel.sensitivity_fsq_noise_fraction}
        sensitivity, paper_model = score_cell("ours", paper, base, data, sel.seed)
        sensitivity["paper_quantiser"] = True
        information = {
            "default": held_out_information(trajs, sel.seed, cell_config(base, chosen),
                                            default, data),
            "paper_quantiser": held_out_information(trajs, sel.seed, cell_config(base, paper),
                                                    paper_model, data),
        }
    return {**result, "world": trajs.world, "seed": sel.seed, "sensitivity": sensitivity,
            "test_information_only": information, "selection_config": sel.model_dump(),
            "base_train_config": base.model_dump(),
            "data_hash": trajectory_hash(trajs),
            "n_windows": {k: len(w) for k, w in data.windows.items() if k != "test"},
            "wall_s": round(time.perf_counter() - started, 1)}


def _choose(rows: list[dict], sel: SelectionConfig) -> dict:
    """Mark the chosen VAE and Ours rows; the chosen values and the rules in words."""
    vae = [row for row in rows if row["model"] == "vae"]
    ours = [row for row in rows if row["model"] == "ours"]
    vae_i = lowest_loss(vae)
    ours_i, any_eligible = choose_ours(ours, sel.ours)
    for i, row in enumerate(ours):
        row["eligible"] = is_eligible(row, sel.ours)
        row["chosen"] = i == ours_i
    for i, row in enumerate(vae):
        row["chosen"] = i == vae_i
    return {"rows": rows, "rules": {"vae": VAE_RULE, "ours": ours_rule(sel.ours)},
            "ours_any_eligible": any_eligible,
            "chosen": {"vae": vae[vae_i]["settings"], "ours": ours[ours_i]["settings"]}}


def yaml_lines(result: dict) -> str:
    """The block to paste under `selected:` in study_configs/training.yaml."""
    vae, ours = result["chosen"]["vae"], result["chosen"]["ours"]
    return "\n".join([f"  {result['world']}:", f"    levels: {json.dumps(ours['levels'])}",
                      f"    beta_kl: {vae['beta_kl']}",
                      f"    vae_latent_dim: {vae['vae_latent_dim']}"]) + "\n"


def markdown(result: dict) -> str:
    """One table of every cell (chosen cells in bold; epochs run and whether the validation
    loss converged before max_epochs) plus the sensitivity row and rules."""
    lines = [f"# Model selection: {result['world']} (seed {result['seed']}, validation split)",
             "", f"- VAE rule: {result['rules']['vae']}", f"- Ours rule: {result['rules']['ours']}",
             "", "| model | setting | val task loss | val pred | val recon | val KL | codes used "
             "| perplexity | epochs | converged | chosen |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in result["rows"] + [result["sensitivity"]]:
        lines.append(_markdown_row(row))
    lines += ["", "Test split, for information only (never used to choose):", ""]
    for name, info in result["test_information_only"].items():
        lines.append(f"- Ours {name}: MSE {info['test_mse']:.4f}, purity "
                     + ", ".join(f"{k} {v:.3f}" for k, v in info["test_purity"].items()))
    return "\n".join(lines) + "\n"


def _markdown_row(row: dict) -> str:
    setting = ", ".join(f"{k} {json.dumps(v)}" for k, v in row["settings"].items())
    kl = "-" if row["val_kl"] is None else f"{row['val_kl']:.3f}"
    codes = (f"{row['codes_used']}/{row['codebook_size']}" if "codes_used" in row else "-")
    ppl = f"{row['perplexity']:.2f}" if "perplexity" in row else "-"
    mark = ("sensitivity" if row.get("paper_quantiser") else
            "**chosen**" if row.get("chosen") else
            "not eligible" if row.get("eligible") is False else "")
    cells = [row["model"], setting, f"{row['val_task_loss']:.4f}", f"{row['val_pred']:.4f}",
             f"{row['val_recon']:.4f}", kl, codes, ppl, str(row["epochs_run"]),
             "yes" if row["converged"] else "no: hit the cap", mark]
    if row.get("chosen"):
        cells[2] = f"**{cells[2]}**"
    return "| " + " | ".join(cells) + " |"


def write_outputs(result: dict, out_dir: Path) -> None:
    """selection.json, selection.md and selected.yaml in out_dir."""
    write_json(out_dir / "selection.json", {**result, "yaml": yaml_lines(result)})
    for name, text in (("selection.md", markdown(result)), ("selected.yaml", yaml_lines(result))):
        with atomic_path(out_dir / name) as tmp:
            tmp.write_text(text)


def select_world(layout: Layout, world: str, config: Path | None = None,
                 train_config: Path | None = None, out: Path | None = None,
                 say: Callable[[str], None] = print, workers: int = 2) -> Path:
    """`tomstudy select`: run the selection for one world, write and say the results.

    Writes into out/<world>/ (default: the layout's selection dir); returns that folder."""
    trajs = simulated_trajectories(layout, world)
    sel, base = load_selection_config(config), load_train_config(train_config)
    result = run_selection(trajs, base, sel, workers)
    result["data_file"] = str(layout.trajectories(world))
    out_dir = out / world if out else layout.selection_dir(world)
    write_outputs(result, out_dir)
    say(markdown(result))
    say(f"wrote {out_dir}/selection.json, selection.md, selected.yaml")
    say("in study_configs/training.yaml, put this under `selected:` (replacing `{}`; keep "
        "other worlds' entries):\n" + yaml_lines(result))
    return out_dir


def chosen_selection(result: dict) -> WorldSelection:
    """The values a selection chose, as training.yaml's `selected` entry holds them."""
    vae, ours = result["chosen"]["vae"], result["chosen"]["ours"]
    return WorldSelection(levels=ours["levels"], beta_kl=vae["beta_kl"],
                          vae_latent_dim=vae["vae_latent_dim"])


def ensure_selected(layout: Layout, worlds: list[str], base: TrainConfig,
                    say: Callable[[str], None] = print,
                    workers: int | JobPool = 2) -> TrainConfig:
    """`base` with a selection for every world: training.yaml's own, else the pre-registered
    rule run now (or its result on this very data, kept in the layout's selection dir).

    A world new to the study (a recorded one, say) gets its sizes by the rules the simulated
    worlds got theirs, on validation data, before any checkpoint of it is trained."""
    chosen = dict(base.selected)
    sel, unselected = load_selection_config(), base.model_copy(update={"selected": {}})
    for world in worlds:
        if world in chosen:
            continue
        out_dir = layout.selection_dir(world)
        trajs = simulated_trajectories(layout, world)
        result = kept_selection(out_dir / "selection.json", trajs, sel, unselected)
        if result is None:
            say(f"{world}: training.yaml selects nothing; running the selection rules of "
                "model_selection.yaml on its validation split")
            result = run_selection(trajs, unselected, sel, workers)
            write_outputs(result, out_dir)
        chosen[world] = chosen_selection(result)
        say(f"{world}: selected {chosen[world].model_dump()} ({out_dir / 'selection.md'})")
    return base.model_copy(update={"selected": chosen})


def kept_selection(path: Path, trajs: TrajectorySet, sel: SelectionConfig,
                   base: TrainConfig) -> dict | None:
    """The selection.json at `path` if it was run on this data with these grids and this
    training config, else None."""
    if not path.is_file():
        return None
    result = json.loads(path.read_text())
    same = (result.get("data_hash") == trajectory_hash(trajs)
            and result.get("selection_config") == json.loads(json.dumps(sel.model_dump()))
            and result.get("base_train_config")
            == json.loads(json.dumps(cell_config(base, {}).model_dump())))
    return result if same else None
