"""The paper's real-data test: Ours vs VAE vs constant velocity on INTERACTION pairs.

Procedure (one command, `tomstudy interaction`):
1. Load the scenario's train and val track files (app.data.interaction), cut 4 s windows,
   pair each car with its nearest interacting car (rule in that module).
2. Downsample 10 Hz -> 5 Hz (every 2nd frame): the observed 1 s (10 frame intervals) is a
   segment of 5 steps of 0.2 s, the study's segment length; the models predict the robot's
   next 3 actions (0.6 s).
3. For each seed (a "trial"), train Ours and the VAE on the train pairs (the trainer splits
   them by pair into fit/early-stopping/test), then on every val window predict the robot's
   next action; alignment error = 1 - cos against the true next action. Windows whose true
   next speed is below `min_speed_mps` are not scored (a standing car has no direction).
4. Per seed mean errors -> paired t-tests (Ours vs VAE, each vs constant velocity), ADE/FDE
   over the n steps, purity/NMI of codes against the manoeuvre labels when the data carry
   them (the generator's sidecar) and against a turn label derived from the robot's heading
   change (always), vector fields per code over the scenario area, HTML + JSON report.
"""

import base64
import csv
import html
import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field
from tqdm import tqdm

import app
from app.configio import StrictModel
from app.data import interaction as ix
from app.data.lanelet_map import LaneLine, MapError, read_lanelet_map
from app.data.trajectory import HUMAN, ROBOT, TrajectorySet
from app.data.windows import Windows, make_windows
from app.fileio import sha256_file, write_json
from app.learning.config import TrainConfig
from app.worlds.scene import HUMAN_COLOR, LABEL_COLORS, ROBOT_COLOR, AgentShape, Bounds, Scene

MODELS = ("ours", "vae", "cv")
MODEL_NAMES = {"ours": "Ours", "vae": "VAE", "cv": "constant velocity"}
TURN_NAMES = ["left", "straight", "right"]
HEADING_NAMES = ["east", "north", "west", "south"]


class InteractionError(ValueError):
    """The experiment cannot run on this data; the message says why."""


class InteractionConfig(StrictModel):
    """How pairs are cut and scored; defaults follow the paper (1 s observed, 10 seeds)."""

    window_frames: int = Field(40, ge=8, description="frames per pair window (4 s at 10 Hz)")
    window_stride_frames: int = Field(40, ge=1, description="v1.0: step between windows")
    observed_frames: int = Field(10, ge=2, description="observed segment: 10 intervals = 1 s")
    downsample: int = Field(2, ge=1, description="keep every k-th frame (k=2: dt 0.2 s)")
    predict_steps: int = Field(3, ge=1, description="n actions predicted (ADE/FDE horizon)")
    pair_max_distance_m: float = Field(30.0, gt=0)
    min_speed_mps: float = Field(0.5, ge=0, description="true next speed needed to score")
    turn_threshold_deg: float = Field(30.0, gt=0, description="heading change = a turn")
    v10_train_fraction: float = Field(0.8, gt=0, lt=1,
                                      description="v1.0 time split without a devkit val list")
    seeds: int = Field(10, ge=2)
    max_train_pairs: int = Field(0, ge=0, description="0 = all; else an even subsample")
    eval_windows_per_pair: int = Field(20, ge=1)
    field_grid: int = Field(25, ge=5, description="grid points per side of a vector field")
    field_codes: int = Field(6, ge=1, description="most used codes drawn per model")

    @property
    def segment_len(self) -> int:
        """Observed steps after downsampling."""
        return self.observed_frames // self.downsample

    @property
    def dt_s(self) -> float:
        """Step of the downsampled pairs."""
        return ix.FRAME_MS / 1000 * self.downsample


@dataclass
class PairData:
    """One split's pairs as a TrajectorySet plus per-step manoeuvre indices [N, 2, T+1]
    (coarse, with arm; -1: unknown)."""

    trajs: TrajectorySet
    step_manoeuvre: np.ndarray | None
    n_pairs: int
    agent_counts: dict[str, int]


@dataclass
class Experiment:
    """Both splits, the map and where everything came from."""

    scenario: str
    layout: str
    train: PairData
    val: PairData
    manoeuvre_names: list[str] | None
    lane_lines: list[LaneLine]
    inputs: dict[str, str]


# ---------------------------------------------------------------- data


def _manoeuvre_lookup(data_dir: Path, scenario: str) -> dict | None:
    files = sorted((Path(data_dir) / "generator_labels").glob(f"{scenario}_*.csv"))
    if not files:
        return None
    table: dict = {}
    for path in files:
        table.update(ix.load_manoeuvres(path))
    return table


def _turn_label(positions: np.ndarray, threshold_deg: float) -> int:
    """left / straight / right from the robot's travel direction change over the window."""
    robot = positions[:, ROBOT]
    moves = np.diff(robot, axis=0)
    moving = np.linalg.norm(moves, axis=1) > 0.05
    if moving.sum() < 2:
        return TURN_NAMES.index("straight")
    angles = np.unwrap(np.arctan2(moves[moving, 1], moves[moving, 0]))
    change = np.degrees(angles[-1] - angles[0])
    if change > threshold_deg:
        return TURN_NAMES.index("left")
    if change < -threshold_deg:
        return TURN_NAMES.index("right")
    return TURN_NAMES.index("straight")


def _pair_manoeuvres(pair: ix.Pair, lookup: dict, names: list[str], step: int) -> np.ndarray:
    """Index into `names` of the robot's manoeuvre at every kept frame (-1: unknown)."""
    frames = pair.first_frame + np.arange(len(pair.positions))[::step]
    return np.array([names.index(lookup[(pair.recording, pair.robot_id, int(f))])
                     if (pair.recording, pair.robot_id, int(f)) in lookup else -1
                     for f in frames], dtype=np.int64)


def coarse_names(detail: list[str]) -> list[str]:
    """'entering:east' -> 'entering': the manoeuvre without its arm."""
    return sorted({name.split(":")[0] for name in detail})


def _majority(steps: np.ndarray) -> int:
    known = steps[steps >= 0]
    return int(np.bincount(known).argmax()) if len(known) else -1


def _to_pair_data(world: str, pairs: list[ix.Pair], cfg: InteractionConfig, scene: Scene,
                  lookup: dict | None, names: list[str] | None,
                  agent_counts: dict[str, int]) -> PairData:
    label_names = {"robot_turn": TURN_NAMES}
    if names is not None:
        coarse = coarse_names(names)
        to_coarse = np.array([coarse.index(n.split(":")[0]) for n in names] + [-1])
        label_names.update(robot_manoeuvre=coarse, robot_manoeuvre_arm=names)
    episodes, per_step = [], []
    for pair in pairs:
        labels = {"robot_turn": _turn_label(pair.positions, cfg.turn_threshold_deg)}
        if names is not None:
            detail = _pair_manoeuvres(pair, lookup, names, cfg.downsample)
            steps = np.stack([to_coarse[detail], detail])  # -1 indexes the trailing -1
            labels.update(robot_manoeuvre=_majority(steps[0]),
                          robot_manoeuvre_arm=_majority(steps[1]))
            per_step.append(steps)
        episodes.append(pair.episode(cfg.downsample, labels))
    trajs = TrajectorySet.from_episodes(world, cfg.dt_s, episodes, label_names, scene)
    return PairData(trajs, np.stack(per_step) if per_step else None, len(pairs), agent_counts)


def _scene(world: str, pairs: list[ix.Pair], dt_s: float) -> Scene:
    xy = np.concatenate([p.positions.reshape(-1, 2) for p in pairs])
    lo, hi = xy.min(axis=0) - 5, xy.max(axis=0) + 5
    car = dict(kind="car", length_m=4.6, width_m=1.9)
    return Scene(world=world, dt_s=dt_s,
                 frame="INTERACTION map frame: x, y [m] as in the track files (y up)",
                 bounds=Bounds(x_min_m=float(lo[0]), x_max_m=float(hi[0]),
                               y_min_m=float(lo[1]), y_max_m=float(hi[1])),
                 agents=[AgentShape(name="robot", color=ROBOT_COLOR, **car),
                         AgentShape(name="human", color=HUMAN_COLOR, **car)])


def _split_pairs(data_dir: Path, scenario: str, cfg: InteractionConfig):
    layout = ix.detect_layout(data_dir, scenario)
    files = ix.split_files(data_dir, scenario, layout)
    out, counts = {}, {}
    if layout == "v1.2":
        for split in ix.SPLITS:
            recs = ix.load_recordings(files[split])
            counts[split] = _agent_counts(recs)
            out[split] = ix.extract_pairs(recs, cfg.window_frames, cfg.window_stride_frames,
                                          cfg.pair_max_distance_m)
    else:
        recs = ix.load_recordings(files["train"])
        val_names = ix.official_val_recordings(data_dir, scenario)
        if val_names and {r.name for r in recs} - set(val_names):
            ranges = ix.recording_split(recs, val_names)
        else:
            ranges = ix.time_split(recs, cfg.v10_train_fraction)
        for split in ix.SPLITS:
            counts[split] = _agent_counts([r for r in recs if r.name in ranges[split]
                                           and ranges[split][r.name][1] >= 0])
            out[split] = ix.extract_pairs(recs, cfg.window_frames, cfg.window_stride_frames,
                                          cfg.pair_max_distance_m, ranges[split])
    inputs = {str(p): sha256_file(p) for p in sorted({f for fs in files.values() for f in fs})}
    return layout, out, counts, inputs


def _agent_counts(recordings: list[ix.Recording]) -> dict[str, int]:
    total: dict[str, int] = {}
    for rec in recordings:
        for kind, n in rec.counts().items():
            total[kind] = total.get(kind, 0) + n
    return total


def load_experiment(data_dir: Path, scenario: str, cfg: InteractionConfig) -> Experiment:
    """Read, validate and pair the scenario's files (TrackFileError on bad files)."""
    layout, pairs, counts, inputs = _split_pairs(data_dir, scenario, cfg)
    need = cfg.observed_frames + cfg.predict_steps * cfg.downsample + 1
    if cfg.window_frames < need:
        raise InteractionError(f"window_frames={cfg.window_frames} is shorter than the "
                               f"{need} frames one observed segment + prediction needs")
    for split in ix.SPLITS:
        if len(pairs[split]) < 3:
            raise InteractionError(f"{scenario}: only {len(pairs[split])} {split} pairs (cars "
                                   f"present for {cfg.window_frames} frames with another car "
                                   f"within {cfg.pair_max_distance_m} m); need at least 3")
    if 0 < cfg.max_train_pairs < len(pairs["train"]):
        keep = np.linspace(0, len(pairs["train"]) - 1, cfg.max_train_pairs).round().astype(int)
        pairs["train"] = [pairs["train"][k] for k in keep]
    world = f"interaction_{scenario}"
    scene = _scene(world, pairs["train"] + pairs["val"], cfg.dt_s)
    lookup = _manoeuvre_lookup(data_dir, scenario)
    names = sorted(set(lookup.values())) if lookup else None
    data = {s: _to_pair_data(world, pairs[s], cfg, scene, lookup, names, counts[s])
            for s in ix.SPLITS}
    map_path = Path(data_dir) / "maps" / f"{scenario}.osm"
    lines = []
    if map_path.is_file():
        try:
            lines = read_lanelet_map(map_path)
        except MapError as err:
            tqdm.write(f"warning: {err}; plots drawn without lane lines")
        inputs[str(map_path)] = sha256_file(map_path)
    return Experiment(scenario, layout, data["train"], data["val"], names, lines, inputs)


# ---------------------------------------------------------------- training and scoring


def experiment_train_config(base: TrainConfig, cfg: InteractionConfig) -> TrainConfig:
    """The training config with the experiment's segment length and horizon."""
    return TrainConfig(**{**base.model_dump(), "segment_len": cfg.segment_len,
                          "n_actions": cfg.predict_steps})


def heading_sector(velocity: np.ndarray) -> np.ndarray:
    """Travel direction [W] as the nearest of east/north/west/south (map frame, y up)."""
    angle = np.arctan2(velocity[:, 1], velocity[:, 0])
    return (np.round(angle / (np.pi / 2)).astype(np.int64) % 4)


def eval_windows(val: PairData, cfg: InteractionConfig) -> Windows:
    """Val windows: 1 s observed + n future steps, evenly spaced in each pair."""
    return make_windows(val.trajs, cfg.segment_len, cfg.predict_steps, cfg.eval_windows_per_pair)


def window_labels(windows: Windows, val: PairData) -> dict[str, np.ndarray]:
    """Per-window labels: manoeuvre at the segment end (if known), the pair's turn label and
    the robot's last observed travel direction."""
    labels = {"robot_turn": windows.labels["robot_turn"].astype(np.int64),
              "robot_heading": heading_sector(windows.actions[:, windows.segment_len - 1, ROBOT])}
    if val.step_manoeuvre is not None:
        for k, name in enumerate(("robot_manoeuvre", "robot_manoeuvre_arm")):
            labels[name] = val.step_manoeuvre[windows.traj_index, k, windows.end_step]
    return labels


def score_model(model, windows: Windows, scored: np.ndarray) -> dict:
    """Alignment errors [W] of the next action, displacement errors, codes."""
    from analysis.metrics import alignment_error
    from app.learning.metrics import trajectory_errors

    z = model.encode_batch(windows.segment_positions)
    pred = model.predict_batch(z, windows.end_states)
    errors = alignment_error(pred[:, 0], windows.pred_targets[:, 0])
    return {"errors": errors, "codes": model.codes_of(z),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


def score_constant_velocity(windows: Windows, scored: np.ndarray) -> dict:
    """The baseline: the last observed robot velocity, kept for all n steps."""
    from analysis.metrics import alignment_error
    from app.learning.metrics import constant_velocity, trajectory_errors

    pred = constant_velocity(windows)
    return {"errors": alignment_error(pred[:, 0], windows.pred_targets[:, 0]),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


def run_seed(exp: Experiment, seed: int, train_cfg: TrainConfig, models_dir: Path,
             windows: Windows, scored: np.ndarray, labels: dict) -> dict:
    """Train Ours then the VAE (its k = Ours' used codes) with `seed`; score both on val."""
    from app.learning.checkpoint import load_model
    from app.learning.metrics import agreement, code_usage
    from app.learning.train import train_model

    out = {"seed": seed}
    for kind in ("ours", "vae"):
        ckpt = train_model(exp.train.trajs, kind, seed, train_cfg,
                           models_dir / f"seed_{seed}" / kind,
                           data_meta={"scenario": exp.scenario, "layout": exp.layout,
                                      "inputs": exp.inputs}, progress=False)
        model = load_model(ckpt)
        scores = score_model(model, windows, scored)
        codes = scores["codes"][scored]
        out[kind] = {
            "alignment_error": float(scores["errors"][scored].mean()),
            **scores["displacement"],
            "usage": code_usage(codes, train_cfg.min_code_share),
            "agreement": agreement(codes, {k: v[scored] for k, v in labels.items()}),
            "checkpoint": str(ckpt), "content_hash": model.content_hash,
        }
    return out


# ---------------------------------------------------------------- the whole run


def run_experiment(data_dir: Path, scenario: str, out_dir: Path, models_dir: Path,
                   cfg: InteractionConfig, base_train_cfg: TrainConfig) -> dict:
    """Everything: load, train 2 x seeds models, score, test, plot, write the report."""
    started = time.perf_counter()
    exp = load_experiment(data_dir, scenario, cfg)
    train_cfg = experiment_train_config(base_train_cfg, cfg)
    windows = eval_windows(exp.val, cfg)
    true_next = windows.pred_targets[:, 0]
    scored = np.hypot(true_next[:, 0], true_next[:, 1]) >= cfg.min_speed_mps
    if scored.sum() < 2:
        raise InteractionError(f"{scenario}: fewer than 2 val windows with a moving robot")
    labels = window_labels(windows, exp.val)
    cv = score_constant_velocity(windows, scored)
    per_seed = []
    bar = tqdm(range(cfg.seeds), desc=f"interaction {scenario}: seeds", unit="seed")
    for seed in bar:
        per_seed.append(run_seed(exp, seed, train_cfg, models_dir, windows, scored, labels))
        bar.set_postfix(ours=f"{per_seed[-1]['ours']['alignment_error']:.3f}",
                        vae=f"{per_seed[-1]['vae']['alignment_error']:.3f}")
    summary = summarise(exp, cfg, windows, scored, labels, per_seed, cv)
    out_dir = Path(out_dir)
    figures = write_figures(exp, cfg, per_seed, summary, windows, scored, out_dir)
    write_report(out_dir, summary, per_seed, figures)
    write_json(out_dir / "meta.json", {
        "scenario": scenario, "layout": exp.layout, "config": cfg.model_dump(),
        "train_config": train_cfg.model_dump(), "inputs_sha256": exp.inputs,
        "checkpoints": {f"seed_{r['seed']}/{k}": r[k]["content_hash"]
                        for r in per_seed for k in ("ours", "vae")},
        "wall_time_s": round(time.perf_counter() - started, 2),
        "package_version": app.__version__, "python": platform.python_version(),
        "numpy": np.__version__})
    return summary


def summarise(exp: Experiment, cfg: InteractionConfig, windows: Windows, scored: np.ndarray,
              labels: dict, per_seed: list[dict], cv: dict) -> dict:
    """Every headline number, JSON-able."""
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
        for name in per_seed[0][m]["agreement"]:
            for key in ("purity", "nmi"):
                models[m][f"{key}_{name}"] = _mean_sd(
                    [r[m]["agreement"][name][key] for r in per_seed])
    models["cv"] = {"alignment_error": {"mean": means["cv"], "sd": 0.0},
                    **{k: {"mean": v, "sd": 0.0} for k, v in cv["displacement"].items()}}
    return {
        "scenario": exp.scenario, "layout": exp.layout, "seeds": len(per_seed),
        "dt_s": cfg.dt_s, "segment_steps": cfg.segment_len, "observed_s":
            cfg.segment_len * cfg.dt_s, "predict_steps": cfg.predict_steps,
        "pairs": {"train": exp.train.n_pairs, "val": exp.val.n_pairs},
        "agents": {"train": exp.train.agent_counts, "val": exp.val.agent_counts},
        "val_windows": int(len(windows)), "val_windows_scored": int(scored.sum()),
        "label_counts": (counts := _label_counts(exp, labels, scored)),
        "purity_chance": {k: max(v.values()) / max(1, sum(v.values()))
                          for k, v in counts.items()},
        "mean_alignment_error": means, "per_seed_alignment_error":
            {m: seed_means[m].tolist() for m in MODELS},
        "tests": tests, "models": models, "winner": winner,
        "winner_margin": means[runner_up] - means[winner], "runner_up": runner_up,
        "map_lines": len(exp.lane_lines),
    }


def _label_counts(exp: Experiment, labels: dict, scored: np.ndarray) -> dict:
    names = {**exp.train.trajs.label_names, "robot_heading": HEADING_NAMES}
    return {k: {names[k][c]: int((v[scored] == c).sum()) for c in range(len(names[k]))}
            for k, v in labels.items()}


def _mean_sd(values) -> dict:
    values = np.asarray(values, dtype=np.float64)
    return {"mean": float(values.mean()), "sd": float(values.std(ddof=1)) if len(values) > 1
            else 0.0}


# ---------------------------------------------------------------- figures


def _axes_over_scene(ax, exp: Experiment) -> None:
    from app.data.lanelet_map import draw_lane_lines

    b = exp.train.trajs.scene.bounds
    draw_lane_lines(ax, exp.lane_lines)
    ax.set_xlim(b.x_min_m, b.x_max_m)
    ax.set_ylim(b.y_min_m, b.y_max_m)  # map frame: y grows upwards
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)


def _save(fig, path: Path) -> Path:
    from app.fileio import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def plot_errors(summary: dict, path: Path) -> Path:
    """Mean next-action alignment error per model with the 10 per-seed means as dots."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.6))
    colors = {"ours": "#0072B2", "vae": "#D55E00", "cv": "#999999"}
    for k, m in enumerate(MODELS):
        values = np.asarray(summary["per_seed_alignment_error"][m])
        ax.bar(k, values.mean(), color=colors[m], alpha=0.75)
        if m != "cv":
            ax.errorbar(k, values.mean(), yerr=values.std(ddof=1), color="k", capsize=4)
            jitter = np.linspace(-0.2, 0.2, len(values))
            ax.plot(k + jitter, values, "o", color="k", ms=3)
    ax.set_xticks(range(len(MODELS)), [MODEL_NAMES[m] for m in MODELS])
    p = summary["tests"]["ours_vs_vae"]["p_two_sided"]
    ax.set_ylabel("alignment error 1 - cos (next action)")
    ax.set_title(f"{summary['scenario']}: {summary['seeds']} seeds; Ours vs VAE p = {p:.2g}",
                 fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_pairs(exp: Experiment, path: Path, count: int = 80) -> Path:
    """Some train pairs over the map: robot coloured by its label, human dashed."""
    import matplotlib.pyplot as plt

    trajs = exp.train.trajs
    name = "robot_manoeuvre" if "robot_manoeuvre" in trajs.labels else "robot_turn"
    names = trajs.label_names[name]
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    _axes_over_scene(ax, exp)
    pick = np.linspace(0, len(trajs) - 1, min(count, len(trajs))).round().astype(int)
    for i in pick:
        cls = int(trajs.labels[name][i])
        ax.plot(*trajs.positions[i, :, HUMAN].T, color=HUMAN_COLOR, lw=0.6, ls="--", alpha=0.5)
        ax.plot(*trajs.positions[i, :, ROBOT].T, lw=1.2,
                color=LABEL_COLORS[cls % len(LABEL_COLORS)] if cls >= 0 else "k")
    handles = [plt.Line2D([], [], color=LABEL_COLORS[k % len(LABEL_COLORS)], label=n)
               for k, n in enumerate(names)]
    handles.append(plt.Line2D([], [], color=HUMAN_COLOR, ls="--", label="human"))
    ax.legend(handles=handles, fontsize=7, loc="upper right")
    ax.set_title(f"{exp.scenario}: {len(pick)} of {len(trajs)} train pairs "
                 f"(robot by {name})", fontsize=9)
    return _save(fig, path)


def field_grid(exp: Experiment, cfg: InteractionConfig) -> np.ndarray:
    """Grid points [G, 2] over the scenario area, kept where robots were seen (within 4 m)."""
    b = exp.train.trajs.scene.bounds
    xs = np.linspace(b.x_min_m, b.x_max_m, cfg.field_grid)
    ys = np.linspace(b.y_min_m, b.y_max_m, cfg.field_grid)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    seen = exp.train.trajs.positions[:, :, ROBOT].reshape(-1, 2)
    cell = 4.0
    occupied = {tuple(k) for k in np.floor(seen / cell).astype(np.int64)}
    keys = np.floor(grid / cell).astype(np.int64)
    near = [any((k[0] + dx, k[1] + dy) in occupied for dx in (-1, 0, 1) for dy in (-1, 0, 1))
            for k in keys]
    return grid[np.array(near, dtype=bool)]


def plot_fields(exp: Experiment, cfg: InteractionConfig, model, codes: np.ndarray,
                windows: Windows, scored: np.ndarray, path: Path) -> Path:
    """Per most-used code: the decoded next robot action over the area (human fixed)."""
    import matplotlib.pyplot as plt

    values, counts = np.unique(codes[scored], return_counts=True)
    top = values[np.argsort(-counts)][: cfg.field_codes]
    grid = field_grid(exp, cfg)
    cols = min(3, len(top))
    rows = int(np.ceil(len(top) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    for ax, code in zip(axes.flat, top, strict=False):
        in_code = scored & (codes == code)
        human = np.median(windows.end_states[in_code, HUMAN], axis=0)
        states = np.stack([grid, np.repeat(human[None], len(grid), axis=0)], axis=1)
        action = model.predict(model.latent_of_code(int(code)), states)[:, 0]
        speed = np.maximum(np.linalg.norm(action, axis=1, keepdims=True), 1e-6)
        _axes_over_scene(ax, exp)
        ends = windows.end_states[in_code, ROBOT]
        ax.plot(ends[:, 0], ends[:, 1], ".", color=ROBOT_COLOR, ms=2, alpha=0.35)
        ax.quiver(grid[:, 0], grid[:, 1], *(action / speed).T, angles="xy", color="#333333",
                  width=0.004, scale=cfg.field_grid * 1.3)
        ax.plot(*human, "s", color=HUMAN_COLOR, ms=7, mec="k")
        ax.set_title(f"{MODEL_NAMES[model.kind]} code {int(code)}: "
                     f"{in_code.sum() / scored.sum():.0%} of val windows", fontsize=8)
    for ax in list(axes.flat)[len(top):]:
        ax.axis("off")
    fig.suptitle(f"{exp.scenario}: next-action field per code (arrows = direction; blue dots "
                 "= robot positions of val windows with this code; square = human)", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def write_figures(exp: Experiment, cfg: InteractionConfig, per_seed: list[dict], summary: dict,
                  windows: Windows, scored: np.ndarray, out_dir: Path) -> list:
    """errors.png, pairs.png and one vector-field figure per model (seed 0's models)."""
    import matplotlib

    matplotlib.use("Agg")
    from app.learning.checkpoint import load_model

    figures = [plot_errors(summary, out_dir / "errors.png"),
               plot_pairs(exp, out_dir / "pairs.png")]
    for kind in ("ours", "vae"):
        model = load_model(Path(per_seed[0][kind]["checkpoint"]))
        codes = model.codes_of(model.encode_batch(windows.segment_positions))
        figures.append(plot_fields(exp, cfg, model, codes, windows, scored,
                                   out_dir / f"fields_{kind}.png"))
    return figures


# ---------------------------------------------------------------- report


def write_report(out_dir: Path, summary: dict, per_seed: list[dict], figures: list[Path]) -> None:
    """summary.json, per_seed.csv and report.html (figures embedded)."""
    write_json(out_dir / "summary.json", summary)
    with open(out_dir / "per_seed.csv", "w", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(["seed", "model", "alignment_error", "ade_m", "fde_m", "codes_used"])
        for r in per_seed:
            for m in ("ours", "vae"):
                writer.writerow([r["seed"], m, f"{r[m]['alignment_error']:.6f}",
                                 f"{r[m]['ade_m']:.6f}", f"{r[m]['fde_m']:.6f}",
                                 r[m]["usage"]["n_codes_used"]])
    (out_dir / "report.html").write_text(render_html(summary, figures))


def _f(value: float, digits: int = 3) -> str:
    return "-" if value is None or value != value else f"{value:.{digits}f}"


def verdict(summary: dict) -> str:
    """One honest sentence: who wins on next-action alignment error and by how much."""
    means = summary["mean_alignment_error"]
    w, r = summary["winner"], summary["runner_up"]
    test = summary["tests"].get(f"{w}_vs_{r}") or summary["tests"].get(f"{r}_vs_{w}")
    return (f"{MODEL_NAMES[w]} has the lowest mean next-action alignment error "
            f"({means[w]:.4f}), {summary['winner_margin']:.4f} below {MODEL_NAMES[r]} "
            f"({means[r]:.4f}; paired t-test over seeds p = {test['p_two_sided']:.2g}).")


def render_html(summary: dict, figures: list[Path]) -> str:
    """The report page."""
    rows = "".join(
        f"<tr><td>{MODEL_NAMES[m]}</td>"
        + "".join(f"<td>{_f(summary['models'][m][k]['mean'])} &plusmn; "
                  f"{_f(summary['models'][m][k]['sd'])}</td>"
                  for k in ("alignment_error", "ade_m", "fde_m")) + "</tr>" for m in MODELS)
    tests = "".join(
        f"<tr><td>{name.replace('_vs_', ' vs ').replace('cv', 'CV')}</td>"
        f"<td>{_f(t['mean_diff'])} [{_f(t['ci95_low'])}, {_f(t['ci95_high'])}]</td>"
        f"<td>{_f(t['t'], 2)}</td><td>{t['p_two_sided']:.3g}</td><td>{_f(t['d_z'], 2)}</td>"
        "</tr>" for name, t in summary["tests"].items())
    latent = "".join(
        f"<tr><td>{MODEL_NAMES[m]}</td><td>{html.escape(k)}</td>"
        f"<td>{_f(v['mean'])} &plusmn; {_f(v['sd'])}</td></tr>"
        for m in ("ours", "vae") for k, v in summary["models"][m].items()
        if k.startswith(("purity", "nmi", "codes_used", "perplexity")))
    images = "".join(
        f"<figure><img alt='{html.escape(p.stem)}' src='data:image/png;base64,"
        f"{base64.b64encode(p.read_bytes()).decode()}'><figcaption>{html.escape(p.name)}"
        "</figcaption></figure>" for p in figures)
    s = summary
    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>INTERACTION {html.escape(s['scenario'])}</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;
font-size:13px;text-align:right}}img{{max-width:100%}}</style></head><body>
<h1>INTERACTION {html.escape(s['scenario'])} ({html.escape(s['layout'])} layout)</h1>
<p><b>{html.escape(verdict(s))}</b></p>
<p>{s['pairs']['train']} train and {s['pairs']['val']} val robot/human pairs; the models see
{s['segment_steps']} steps of {s['dt_s']:.1f} s ({s['observed_s']:.1f} s, 10 Hz downsampled)
and predict {s['predict_steps']} robot actions. {s['val_windows_scored']} of
{s['val_windows']} val windows are scored (true next speed at least the threshold).
Alignment error = 1 - cos between predicted and true next action (0 same direction,
2 opposite). Mean &plusmn; SD over {s['seeds']} seeds (training runs); constant velocity is
deterministic.</p>
<h2>Errors</h2><table><tr><th>model</th><th>alignment error</th><th>ADE [m]</th>
<th>FDE [m]</th></tr>{rows}</table>
<h2>Paired t-tests over seeds (difference = first - second)</h2>
<p>Constant velocity gives the same value for every seed, so its comparisons are in effect
one-sample t-tests of the seed means against that value.</p>
<table><tr><th>comparison</th><th>mean diff [95% CI]</th><th>t</th><th>p</th><th>d_z</th></tr>
{tests}</table>
<h2>Latent codes vs labels (val windows)</h2><table><tr><th>model</th><th>measure</th>
<th>mean &plusmn; SD</th></tr>{latent}</table>
<p>Purity if every window got the most common label (chance level):
{html.escape(", ".join(f"{k} {v:.3f}" for k, v in s["purity_chance"].items()))}.</p>
<p>Label counts: {html.escape(json.dumps(s['label_counts']))}</p>
<h2>Figures</h2>{images}
<p>All numbers: summary.json and per_seed.csv beside this file.</p></body></html>
"""


# ---------------------------------------------------------------- command line


def load_config(path: Path | None, seeds: int | None) -> InteractionConfig:
    """The experiment config: defaults, a YAML file's keys on top, then --seeds."""
    from app.configio import load_yaml_model

    overrides = {"seeds": seeds} if seeds is not None else {}
    if path is None:
        return InteractionConfig(**overrides)
    return load_yaml_model(Path(path), InteractionConfig, overrides)


def run_command(data_dir: Path, scenario: str, data_root: Path, config: Path | None = None,
                train_config: Path | None = None, seeds: int | None = None,
                max_epochs: int | None = None, out_dir: Path | None = None) -> dict:
    """What `tomstudy interaction` does: returns the summary; outputs under data_root."""
    from app.learning.config import load_train_config

    cfg = load_config(config, seeds)
    overrides = {"max_epochs": max_epochs} if max_epochs else None
    base = load_train_config(train_config, overrides)
    out_dir = Path(out_dir) if out_dir else Path(data_root) / "reports" / "interaction" / scenario
    models_dir = Path(data_root) / "models" / "interaction" / scenario
    return run_experiment(Path(data_dir), scenario, out_dir, models_dir, cfg, base)
