"""The paper's real-data test: Ours vs VAE vs constant velocity on INTERACTION pairs.

Procedure (one command, `tomstudy interaction`):
1. Load the scenario's train and val track files (app/recordings/tracks.py), cut 4 s
   windows, pair each car with its nearest interacting car (rule in app/recordings/pairs.py).
   Choose Ours' FSQ levels on validation loss of the train pairs (codes.py), before anything
   is scored.
2. Downsample 10 Hz -> 5 Hz (every 2nd frame): the observed 1 s (10 frame intervals) is a
   segment of 5 steps of 0.2 s, the study's segment length; the models predict the robot's
   next 3 actions (0.6 s).
3. For each seed (a "trial"), train Ours and the VAE on the train pairs (the trainer splits
   them by pair into fit/early-stopping/test), then on every val window predict the robot's
   next action; alignment error = 1 - cos against the true next action. Windows whose true
   next speed is below `min_speed_mps` are not scored (a standing car has no direction).
   The seeds (with step 5's and step 1's levels cells) run on `workers` processes
   (app/learning/jobs.py, `--workers`, default 2), torch on one thread in each: a seed's
   numbers do not depend on how many processes ran.
4. Per seed mean errors -> paired t-tests (Ours vs VAE, each vs constant velocity), ADE/FDE
   over the n steps, purity/NMI of codes against the manoeuvre labels when the data carry
   them (the generator's sidecar) and against a turn label derived from the robot's heading
   change (always), each beside a supervised ceiling and chance (codes.py), vector fields
   per code over the scenario area, HTML + JSON report.
5. The sensitivity row (frames.py): steps 3-4's next action and paired tests again, with
   both models trained and scored on positions relative to the human car ("from the other
   car's point of view"), on fewer seeds (study_configs/interaction.yaml).
"""

import platform
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

import app
from app.core.files import write_json
from app.data.windows import Windows
from app.interaction.codes import (
    CEILING,
    ceiling_scores,
    choose_levels,
    code_purity,
    held_out_purity,
)
from app.interaction.config import InteractionConfig, load_config
from app.interaction.dataset import (
    HEADING_NAMES,
    InteractionError,
    ScenarioData,
    eval_windows,
    load_scenario_data,
    window_labels,
)
from app.interaction.frames import Frame, in_frame
from app.interaction.horizons import (
    HorizonWindows,
    constant_velocity_rollout,
    horizon_key,
    horizon_scores,
    horizon_windows,
    model_rollout,
    summarise_by_horizon,
)
from app.interaction.report import FigureInputs, write_figures, write_report
from app.layout import Layout
from app.learning.config import TrainConfig
from app.learning.jobs import JobPool, job_pool
from app.learning.train import train_and_save

MODELS = ("ours", "vae", "cv")


def experiment_train_config(base: TrainConfig, cfg: InteractionConfig) -> TrainConfig:
    """The training config with the experiment's segment length and horizon."""
    return TrainConfig(**{**base.model_dump(), "segment_len": cfg.segment_len,
                          "n_actions": cfg.predict_steps})


def with_levels(train_cfg: TrainConfig, levels: list[int]) -> TrainConfig:
    """The training config with Ours' chosen FSQ levels."""
    return TrainConfig(**{**train_cfg.model_dump(), "levels": levels})


@dataclass(frozen=True)
class TrainerWindows:
    """The trainer's split windows of the train pairs ('train', 'val', 'test') and labels."""

    windows: dict[str, Windows]
    labels: dict[str, dict[str, np.ndarray]]


def trainer_windows(exp: ScenarioData, train_cfg: TrainConfig) -> TrainerWindows:
    """The windows Ours fits on and stops early on, as the trainer cuts them."""
    from app.learning.train import prepare_windows

    windows = prepare_windows(exp.train.trajs, train_cfg)
    return TrainerWindows(windows, {k: window_labels(w, exp.train) for k, w in windows.items()})


def score_model(model, windows: Windows, scored: np.ndarray,
                frame: Frame = "absolute") -> dict:
    """Alignment errors [W] of the next action, displacement errors, codes; the model sees
    the windows in its `frame` and is scored against the same true actions in every frame."""
    from app.core.alignment import alignment_error
    from app.learning.model_metrics import trajectory_errors

    seen = in_frame(windows, frame)
    z = model.encode_batch(seen.segment_positions)
    pred = model.predict_batch(z, seen.end_states)
    errors = alignment_error(pred[:, 0], windows.pred_targets[:, 0])
    return {"errors": errors, "codes": model.codes_of(z),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


def protocol_scores(model, on: "Scoring", min_code_share: float,
                    frame: Frame = "absolute") -> tuple[dict, np.ndarray]:
    """One model's row of the paper's protocol (mean next-action alignment error over the
    scored windows, displacement errors, code usage) and its codes on the scored windows."""
    from app.learning.model_metrics import code_usage

    scores = score_model(model, on.windows, on.scored, frame)
    codes = scores["codes"][on.scored]
    return {"alignment_error": float(scores["errors"][on.scored].mean()),
            **scores["displacement"], "usage": code_usage(codes, min_code_share)}, codes


def score_constant_velocity(windows: Windows, scored: np.ndarray) -> dict:
    """The baseline: the last observed robot velocity, kept for all n steps."""
    from app.core.alignment import alignment_error
    from app.learning.model_metrics import constant_velocity, trajectory_errors

    pred = constant_velocity(windows)
    return {"errors": alignment_error(pred[:, 0], windows.pred_targets[:, 0]),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


@dataclass(frozen=True)
class Scoring:
    """What every seed's models are scored on: the val windows (which are scored, their
    labels), the secondary horizons, and the trainer's windows for held-out purity."""

    windows: Windows
    scored: np.ndarray
    labels: dict[str, np.ndarray]
    horizons: list[HorizonWindows]
    trainer: TrainerWindows


def held_out(model, codes: np.ndarray, on: Scoring) -> dict[str, float]:
    """Per label: each code's majority label on the train windows, accuracy on val."""
    train = on.trainer.windows["train"]
    train_codes = model.codes_of(model.encode_batch(train.segment_positions))
    return {name: held_out_purity(train_codes, on.trainer.labels["train"][name], codes,
                                  values[on.scored])
            for name, values in on.labels.items()}


def train_pair(exp: ScenarioData, seed: int, train_cfg: TrainConfig, models_dir: Path,
               frame: Frame):
    """Train Ours, then the VAE with k = Ours' used codes, in `frame`; yields (kind, checkpoint
    path, loaded model) as each is trained."""
    from app.learning.checkpoint import load_model

    meta = {"scenario": exp.scenario, "layout": exp.layout, "inputs": exp.inputs}
    moved = frame != "absolute"  # the primary's checkpoints stay exactly as they were
    if moved:
        meta["frame"] = frame
    transform = partial(in_frame, frame=frame) if moved else None
    ours_codes = None
    for kind in ("ours", "vae"):
        ckpt = train_and_save(exp.train.trajs, kind, seed, train_cfg,
                              models_dir / f"seed_{seed}" / kind, data_meta=meta, progress=False,
                              vae_clusters=ours_codes, transform=transform)
        model = load_model(ckpt)
        if kind == "ours":
            ours_codes = model.codes["n_codes_used"]  # the VAE's k-means k
        yield kind, ckpt, model


def run_seed(exp: ScenarioData, seed: int, train_cfg: TrainConfig, models_dir: Path,
             on: Scoring) -> dict:
    """Train Ours then the VAE (its k = Ours' used codes) with `seed`; score both on val:
    the paper's next action, then each secondary horizon."""
    from app.learning.model_metrics import agreement

    out = {"seed": seed}
    for kind, ckpt, model in train_pair(exp, seed, train_cfg, models_dir, "absolute"):
        row, codes = protocol_scores(model, on, train_cfg.min_code_share)
        out[kind] = {
            **row,
            "agreement": agreement(codes, {k: v[on.scored] for k, v in on.labels.items()}),
            "held_out": held_out(model, codes, on),
            "checkpoint": str(ckpt), "content_hash": model.content_hash,
            "by_horizon": {horizon_key(hw.horizon_s): horizon_scores(
                model_rollout(model, hw.windows, hw.steps), hw) for hw in on.horizons},
        }
    return out


# ---------------------------------------------------------------- the whole run


def scoring_set(exp: ScenarioData, cfg: InteractionConfig, train_cfg: TrainConfig) -> Scoring:
    """Val windows of the paper's protocol (scored where the robot moves), their labels, the
    secondary horizons and the trainer's windows."""
    windows = eval_windows(exp.val, cfg)
    true_next = windows.pred_targets[:, 0]
    scored = np.hypot(true_next[:, 0], true_next[:, 1]) >= cfg.min_speed_mps
    if scored.sum() < 2:
        raise InteractionError(f"{exp.scenario}: fewer than 2 val windows with a moving robot")
    horizons = horizon_windows(exp.horizon_val, cfg.segment_len, cfg.secondary,
                               cfg.min_speed_mps)
    return Scoring(windows, scored, window_labels(windows, exp.val), horizons,
                   trainer_windows(exp, train_cfg))


def frame_seed(exp: ScenarioData, seed: int, train_cfg: TrainConfig, models_dir: Path,
               on: Scoring, frame: Frame) -> dict:
    """The sensitivity row's seed: Ours and the VAE trained and scored in `frame`."""
    out = {"seed": seed}
    for kind, _, model in train_pair(exp, seed, train_cfg, models_dir, frame):
        out[kind] = protocol_scores(model, on, train_cfg.min_code_share, frame)[0]
    return out


def seed_job(frame: Frame, exp: ScenarioData, seed: int, train_cfg: TrainConfig,
             models_dir: Path, on: Scoring) -> dict:
    """A primary seed (run_seed) in the map frame, else a sensitivity row's (frame_seed)."""
    if frame == "absolute":
        return run_seed(exp, seed, train_cfg, models_dir, on)
    return frame_seed(exp, seed, train_cfg, models_dir / frame, on, frame)


def train_seeds(exp: ScenarioData, cfg: InteractionConfig, train_cfg: TrainConfig,
                models_dir: Path, on: Scoring, pool: JobPool) -> tuple[list[dict], list[dict]]:
    """Every primary seed and the sensitivity row's, as one batch on `pool`'s workers with one
    progress bar; (primary rows, sensitivity rows), each in seed order."""
    row = cfg.frame_sensitivity
    frames = [("absolute", seed) for seed in range(cfg.seeds)]
    frames += [(row.frame, seed) for seed in range(row.seeds)]
    jobs = [(frame, exp, seed, train_cfg, models_dir, on) for frame, seed in frames]
    desc = f"interaction {exp.scenario}: seeds (+{row.seeds} {row.frame} frame)"
    rows = pool.run(seed_job, jobs, desc, "seed", _errors_postfix)
    return rows[:cfg.seeds], rows[cfg.seeds:]


def _errors_postfix(row: dict) -> dict:
    return {m: f"{row[m]['alignment_error']:.3f}" for m in ("ours", "vae")}


@dataclass(frozen=True)
class Trained:
    """The training phases' outcome: Ours' levels, what every seed is scored on, the primary
    and sensitivity rows per seed, and each phase's wall time."""

    levels: dict
    train_cfg: TrainConfig
    on: Scoring
    per_seed: list[dict]
    frame_rows: list[dict]
    wall_s: dict[str, float]


def train_all(exp: ScenarioData, cfg: InteractionConfig, base_train_cfg: TrainConfig,
              models_dir: Path, workers: int | JobPool) -> Trained:
    """Choose Ours' levels, then train and score every seed; both phases on `workers`
    processes (one pool, started once, or the pool given)."""
    started = time.perf_counter()
    train_cfg = experiment_train_config(base_train_cfg, cfg)
    with job_pool(workers) as pool:
        levels = choose_levels(exp.train.trajs, train_cfg, cfg.code_levels, pool)  # before purity
        chosen = time.perf_counter()
        train_cfg = with_levels(train_cfg, levels["levels"])
        on = scoring_set(exp, cfg, train_cfg)
        per_seed, frame_rows = train_seeds(exp, cfg, train_cfg, models_dir, on, pool)
    wall_s = {"levels": chosen - started, "seeds": time.perf_counter() - chosen}
    return Trained(levels, train_cfg, on, per_seed, frame_rows, wall_s)


def run_experiment(data_dir: Path, scenario: str, out_dir: Path, models_dir: Path,
                   cfg: InteractionConfig, base_train_cfg: TrainConfig, workers: int = 2) -> dict:
    """Everything: load, choose Ours' levels, train 2 x seeds models (on `workers`
    processes), score, test, plot, write the report."""
    started = time.perf_counter()
    exp = load_scenario_data(data_dir, scenario, cfg)
    loaded = time.perf_counter()
    with JobPool(workers) as pool:  # the trainings' workers fit the ceilings too
        run = train_all(exp, cfg, base_train_cfg, models_dir, pool)
        trained = time.perf_counter()
        on = run.on
        ceiling = ceiling_scores(on.trainer.windows, on.trainer.labels, on.windows, on.labels,
                                 on.scored, pool)
    per_seed = run.per_seed
    cv = score_constant_velocity(on.windows, on.scored)
    summary = summarise(exp, cfg, on.windows, on.scored, on.labels, per_seed, cv)
    summary.update(secondary_results(exp, cfg, on.horizons, per_seed))
    summary.update(frame_sensitivity(cfg, on, cv, run.frame_rows))
    summary.update(fsq_levels=run.levels, ceiling_model=CEILING,
                   code_purity=code_purity(per_seed, ceiling))
    out_dir = Path(out_dir)
    inputs = FigureInputs(exp.scenario, exp.train.trajs, exp.lane_lines, on.windows, on.scored,
                          cfg.field_grid, cfg.field_codes)
    write_report(out_dir, summary, per_seed, write_figures(inputs, per_seed, summary, out_dir))
    wall_s = {"load": loaded - started, **run.wall_s, "report": time.perf_counter() - trained}
    write_json(out_dir / "meta.json", {
        "scenario": scenario, "layout": exp.layout, "config": cfg.model_dump(),
        "train_config": run.train_cfg.model_dump(), "inputs_sha256": exp.inputs,
        "checkpoints": {f"seed_{r['seed']}/{k}": r[k]["content_hash"]
                        for r in per_seed for k in ("ours", "vae")},
        "workers": workers, "wall_time_s": round(time.perf_counter() - started, 2),
        "phase_wall_time_s": {k: round(v, 2) for k, v in wall_s.items()},
        "package_version": app.__version__, "python": platform.python_version(),
        "numpy": np.__version__})
    return summary


def summarise(exp: ScenarioData, cfg: InteractionConfig, windows: Windows, scored: np.ndarray,
              labels: dict, per_seed: list[dict], cv: dict) -> dict:
    """Every headline number, JSON-able."""
    counts = _label_counts(exp, labels, scored)
    return {
        "scenario": exp.scenario, "layout": exp.layout, "seeds": len(per_seed),
        "dt_s": cfg.dt_s, "segment_steps": cfg.segment_len, "observed_s":
            cfg.segment_len * cfg.dt_s, "predict_steps": cfg.predict_steps,
        "pairs": {"train": exp.train.n_pairs, "val": exp.val.n_pairs,
                  "train_found": exp.train_pairs_found},
        "agents": {"train": exp.train.agent_counts, "val": exp.val.agent_counts},
        "label_counts": counts,
        "map_lines": len(exp.lane_lines),
        "paper_protocol": paper_protocol(windows, scored, per_seed, cv),
    }


def paper_protocol(windows: Windows, scored: np.ndarray, per_seed: list[dict], cv: dict) -> dict:
    """The paper's protocol from per-seed scores: means, paired tests, the winner."""
    from analysis.stats import paired_comparison

    seed_means = {m: np.array([r[m]["alignment_error"] for r in per_seed])
                  for m in ("ours", "vae")}
    seed_means["cv"] = np.full(len(per_seed), float(cv["errors"][scored].mean()))
    tests = {f"{a}_vs_{b}": paired_comparison(seed_means[a], seed_means[b]).as_dict()
             for a, b in (("ours", "vae"), ("ours", "cv"), ("vae", "cv"))}
    means = {m: float(seed_means[m].mean()) for m in MODELS}
    winner = min(means, key=means.get)
    runner_up = sorted(means, key=means.get)[1]
    models = {}
    for m in ("ours", "vae"):
        models[m] = {key: _mean_sd([r[m][key] for r in per_seed])
                     for key in ("alignment_error", "ade_m", "fde_m", "mse")}
        models[m]["codes_used"] = _mean_sd([r[m]["usage"]["n_codes_used"] for r in per_seed])
        models[m]["perplexity"] = _mean_sd([r[m]["usage"]["perplexity"] for r in per_seed])
    models["cv"] = {"alignment_error": {"mean": means["cv"], "sd": 0.0},
                    **{k: {"mean": v, "sd": 0.0} for k, v in cv["displacement"].items()}}
    return {
        "val_windows": int(len(windows)), "val_windows_scored": int(scored.sum()),
        "mean_alignment_error": means, "per_seed_alignment_error":
            {m: seed_means[m].tolist() for m in MODELS},
        "tests": tests, "models": models, "winner": winner,
        "winner_margin": means[runner_up] - means[winner], "runner_up": runner_up,
    }


def frame_sensitivity(cfg: InteractionConfig, on: Scoring, cv: dict,
                      per_seed: list[dict]) -> dict:
    """`sensitivity`: the paper's protocol with both models trained and scored in the
    configured frame (seeds 0..k-1 from `frame_seed`, Ours' levels as chosen for the
    primary); {} when off. Constant velocity does not depend on the frame (a translation
    keeps every velocity)."""
    row = cfg.frame_sensitivity
    if row.seeds == 0:
        return {}
    result = paper_protocol(on.windows, on.scored, per_seed, cv)
    return {"sensitivity": {f"{row.frame}_frame": {**result, "frame": row.frame,
                                                    "seeds": row.seeds}}}


def secondary_results(exp: ScenarioData, cfg: InteractionConfig,
                      horizons: list[HorizonWindows], per_seed: list[dict]) -> dict:
    """`by_horizon` and `secondary` (tests, winners, what could not be measured)."""
    cv = {horizon_key(hw.horizon_s): horizon_scores(
        constant_velocity_rollout(hw.windows, hw.steps), hw) for hw in horizons}
    seeds = [{h: {st: {m: r[m]["by_horizon"][h][st] for m in ("ours", "vae")}
                  for st in r["ours"]["by_horizon"][h]} for h in cv} for r in per_seed]
    by_horizon, secondary = summarise_by_horizon(horizons, seeds, cv, cfg.secondary.alpha)
    measured = {hw.horizon_s for hw in horizons}
    secondary["not_measurable"] = {
        horizon_key(h): f"val pairs span {exp.horizon_val.trajs.positions.shape[1] - 1} steps "
                        f"of {cfg.dt_s:g} s: 1 s observed + {h:g} s does not fit"
        for h in cfg.secondary.horizons_s if h not in measured}
    secondary["pairs"] = exp.horizon_val.n_pairs
    secondary["config"] = cfg.secondary.model_dump()
    return {"by_horizon": by_horizon, "secondary": secondary}


def _label_counts(exp: ScenarioData, labels: dict, scored: np.ndarray) -> dict:
    names = {**exp.train.trajs.label_names, "robot_heading": HEADING_NAMES}
    return {k: {names[k][c]: int((v[scored] == c).sum()) for c in range(len(names[k]))}
            for k, v in labels.items()}


def _mean_sd(values) -> dict:
    values = np.asarray(values, dtype=np.float64)
    return {"mean": float(values.mean()), "sd": float(values.std(ddof=1)) if len(values) > 1
            else 0.0}


# ---------------------------------------------------------------- command line


def run_command(data_dir: Path, scenario: str, layout: Layout, config: Path | None = None,
                train_config: Path | None = None, seeds: int | None = None,
                max_epochs: int | None = None, out_dir: Path | None = None,
                frame_seeds: int | None = None, workers: int = 2) -> dict:
    """What `tomstudy interaction` does on the dataset in `data_dir`, training on `workers`
    processes: returns the summary; models and report go under `layout`."""
    from app.learning.config import load_train_config

    cfg = load_config(config, seeds, frame_seeds)
    overrides = {"max_epochs": max_epochs} if max_epochs else None
    base = load_train_config(train_config, overrides)
    out_dir = Path(out_dir) if out_dir else layout.interaction_report(scenario)
    models_dir = layout.interaction_models(scenario)
    return run_experiment(Path(data_dir), scenario, out_dir, models_dir, cfg, base,
                          workers)
