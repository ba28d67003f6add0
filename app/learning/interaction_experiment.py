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
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR, AgentShape, Bounds, Scene
from app.data.trajectory import ROBOT, TrajectorySet
from app.data.windows import Windows, make_windows
from app.fileio import sha256_file, write_json
from app.learning.config import TrainConfig
from app.learning.interaction_report import FigureInputs, write_figures, write_report

MODELS = ("ours", "vae", "cv")
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
    from analysis.contracts import alignment_error
    from app.learning.model_metrics import trajectory_errors

    z = model.encode_batch(windows.segment_positions)
    pred = model.predict_batch(z, windows.end_states)
    errors = alignment_error(pred[:, 0], windows.pred_targets[:, 0])
    return {"errors": errors, "codes": model.codes_of(z),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


def score_constant_velocity(windows: Windows, scored: np.ndarray) -> dict:
    """The baseline: the last observed robot velocity, kept for all n steps."""
    from analysis.contracts import alignment_error
    from app.learning.model_metrics import constant_velocity, trajectory_errors

    pred = constant_velocity(windows)
    return {"errors": alignment_error(pred[:, 0], windows.pred_targets[:, 0]),
            "displacement": trajectory_errors(pred[scored], windows.pred_targets[scored],
                                              windows.dt_s)}


def run_seed(exp: Experiment, seed: int, train_cfg: TrainConfig, models_dir: Path,
             windows: Windows, scored: np.ndarray, labels: dict) -> dict:
    """Train Ours then the VAE (its k = Ours' used codes) with `seed`; score both on val."""
    from app.learning.checkpoint import load_model
    from app.learning.model_metrics import agreement, code_usage
    from app.learning.train import train_and_save

    out, ours_codes = {"seed": seed}, None
    for kind in ("ours", "vae"):
        ckpt = train_and_save(exp.train.trajs, kind, seed, train_cfg,
                              models_dir / f"seed_{seed}" / kind,
                              data_meta={"scenario": exp.scenario, "layout": exp.layout,
                                         "inputs": exp.inputs}, progress=False,
                              vae_clusters=ours_codes)
        model = load_model(ckpt)
        if kind == "ours":
            ours_codes = model.codes["n_codes_used"]  # the VAE's k-means k
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
    inputs = FigureInputs(exp.scenario, exp.train.trajs, exp.lane_lines, windows, scored,
                          cfg.field_grid, cfg.field_codes)
    figures = write_figures(inputs, per_seed, summary, out_dir)
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
    from app.layout import Layout
    from app.learning.config import load_train_config

    cfg = load_config(config, seeds)
    overrides = {"max_epochs": max_epochs} if max_epochs else None
    base = load_train_config(train_config, overrides)
    layout = Layout(data_root)
    out_dir = Path(out_dir) if out_dir else layout.interaction_report(scenario)
    models_dir = layout.interaction_models(scenario)
    return run_experiment(Path(data_dir), scenario, out_dir, models_dir, cfg, base)
