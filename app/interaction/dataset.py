"""A scenario's pairs as trajectories: splits, labels, the scene box, the map and val windows.

Pairs (app/recordings/pairs.py) are downsampled 10 Hz -> 5 Hz into a TrajectorySet per
split; each pair is labelled with the robot's turn over the window (`robot_turn`, from its
motion, always) and, when the generator's sidecar exists, the robot's manoeuvre labels at
every kept step (`entry_arm`, `exit_arm`, `turn`, and `phase` on a roundabout;
synthetic_tracks.LABEL_VALUES).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from app.core.files import sha256_file
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR, AgentShape, Bounds, Scene
from app.data.trajectory import ROBOT, TrajectorySet
from app.data.windows import Windows, make_windows
from app.interaction.config import InteractionConfig
from app.recordings import pairs as px
from app.recordings import tracks as tx
from app.recordings.lanelet_map import LaneLine, MapError, read_lanelet_map
from app.recordings.pairs import TURN_NAMES, turn_label
from app.recordings.synthetic_tracks import LABEL_VALUES, read_manoeuvre_labels

HEADING_NAMES = ["east", "north", "west", "south"]


class InteractionError(ValueError):
    """The experiment cannot run on this data; the message says why."""


@dataclass
class PairData:
    """One split's pairs as a TrajectorySet plus, per generator label, the robot's value
    index at every kept step [N, T+1] (-1: unknown; empty without a sidecar)."""

    trajs: TrajectorySet
    step_labels: dict[str, np.ndarray]
    n_pairs: int
    agent_counts: dict[str, int]


@dataclass
class ScenarioData:
    """Both splits, the map and where everything came from."""

    scenario: str
    layout: str
    train: PairData
    val: PairData
    lane_lines: list[LaneLine]
    inputs: dict[str, str]
    horizon_val: PairData  # val pairs long enough for the secondary horizons (v1.0), else val
    train_pairs_found: int  # before the max_train_pairs cap


def _manoeuvre_lookup(data_dir: Path, scenario: str) -> dict | None:
    files = sorted((Path(data_dir) / "generator_labels").glob(f"{scenario}_*.csv"))
    if not files:
        return None
    table: dict = {}
    for path in files:
        table.update(read_manoeuvre_labels(path))
    return table


def _pair_step_labels(pair: px.Pair, lookup: dict, names: list[str], step: int) -> np.ndarray:
    """Index into LABEL_VALUES of each label in `names` at every kept frame [L, T+1]
    (-1: unknown)."""
    frames = pair.first_frame + np.arange(len(pair.positions))[::step]
    rows = [lookup.get((pair.recording, pair.robot_id, int(f)), {}) for f in frames]
    out = np.full((len(names), len(frames)), -1, dtype=np.int64)
    for k, name in enumerate(names):
        out[k] = [LABEL_VALUES[name].index(row[name]) if name in row else -1 for row in rows]
    return out


def generator_label_names(lookup: dict | None) -> list[str]:
    """The sidecar's labels that some row carries (`phase` only on a roundabout)."""
    seen = {name for row in (lookup or {}).values() for name in row}
    return [name for name in LABEL_VALUES if name in seen]


def _majority(steps: np.ndarray) -> int:
    known = steps[steps >= 0]
    return int(np.bincount(known).argmax()) if len(known) else -1


def _to_pair_data(world: str, pairs: list[px.Pair], cfg: InteractionConfig, scene: Scene,
                  lookup: dict | None, agent_counts: dict[str, int]) -> PairData:
    names = generator_label_names(lookup)
    label_names = {"robot_turn": TURN_NAMES, **{n: list(LABEL_VALUES[n]) for n in names}}
    episodes, per_step = [], []
    for pair in pairs:
        labels = {"robot_turn": turn_label(pair.positions[:, ROBOT], cfg.turn_threshold_deg)}
        steps = _pair_step_labels(pair, lookup or {}, names, cfg.downsample)
        labels.update({name: _majority(row) for name, row in zip(names, steps, strict=True)})
        per_step.append(steps)
        episodes.append(pair.episode(cfg.downsample, labels))
    trajs = TrajectorySet.from_episodes(world, cfg.dt_s, episodes, label_names, scene)
    step_labels = {name: np.stack([steps[k] for steps in per_step])
                   for k, name in enumerate(names)}
    return PairData(trajs, step_labels, len(pairs), agent_counts)


def _scene(world: str, pairs: list[px.Pair], dt_s: float) -> Scene:
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
    layout = tx.detect_layout(data_dir, scenario)
    files = tx.split_files(data_dir, scenario, layout)
    out, counts = {}, {}
    if layout == "v1.2":
        for split in tx.SPLITS:
            recs = tx.load_recordings(files[split])
            counts[split] = _agent_counts(recs)
            out[split] = px.extract_pairs(recs, cfg.window_frames, cfg.window_stride_frames,
                                          cfg.pair_max_distance_m)
    else:
        recs = tx.load_recordings(files["train"])
        ranges = px.v10_split(data_dir, scenario, recs, cfg.v10_train_fraction,
                              cfg.v10_validation_list == "use",
                              "v10_validation_list: ignore in the --config YAML")
        for split in tx.SPLITS:
            counts[split] = _agent_counts([r for r in recs if r.name in ranges[split]
                                           and ranges[split][r.name][1] >= 0])
            out[split] = px.extract_pairs(recs, cfg.window_frames, cfg.window_stride_frames,
                                          cfg.pair_max_distance_m, ranges[split])
        out["horizon_val"] = px.extract_pairs(recs, cfg.secondary.v10_window_frames,
                                              cfg.window_stride_frames, cfg.pair_max_distance_m,
                                              ranges["val"])
    inputs = {str(p): sha256_file(p) for p in sorted({f for fs in files.values() for f in fs})}
    return layout, out, counts, inputs


def _agent_counts(recordings: list[tx.Recording]) -> dict[str, int]:
    total: dict[str, int] = {}
    for rec in recordings:
        for kind, n in rec.counts().items():
            total[kind] = total.get(kind, 0) + n
    return total


def load_scenario_data(data_dir: Path, scenario: str, cfg: InteractionConfig) -> ScenarioData:
    """Read, validate and pair the scenario's files (TrackFileError on bad files)."""
    layout, pairs, counts, inputs = _split_pairs(data_dir, scenario, cfg)
    need = cfg.observed_frames + cfg.predict_steps * cfg.downsample + 1
    if cfg.window_frames < need:
        raise InteractionError(f"window_frames={cfg.window_frames} is shorter than the "
                               f"{need} frames one observed segment + prediction needs")
    for split in tx.SPLITS:
        if len(pairs[split]) < 3:
            raise InteractionError(f"{scenario}: only {len(pairs[split])} {split} pairs (cars "
                                   f"present for {cfg.window_frames} frames with another car "
                                   f"within {cfg.pair_max_distance_m} m); need at least 3")
    found = len(pairs["train"])
    if 0 < cfg.max_train_pairs < found:
        keep = np.linspace(0, len(pairs["train"]) - 1, cfg.max_train_pairs).round().astype(int)
        pairs["train"] = [pairs["train"][k] for k in keep]
    world = f"interaction_{scenario}"
    scene = _scene(world, pairs["train"] + pairs["val"], cfg.dt_s)
    lookup = _manoeuvre_lookup(data_dir, scenario)
    data = {s: _to_pair_data(world, pairs[s], cfg, scene, lookup, counts[s])
            for s in tx.SPLITS}
    long_val = pairs.get("horizon_val") or []
    horizon_val = _to_pair_data(world, long_val, cfg, scene, lookup, counts["val"]) \
        if len(long_val) >= 3 else data["val"]
    map_path = Path(data_dir) / "maps" / f"{scenario}.osm"
    lines = []
    if map_path.is_file():
        try:
            lines = read_lanelet_map(map_path)
        except MapError as err:
            tqdm.write(f"warning: {err}; plots drawn without lane lines")
        inputs[str(map_path)] = sha256_file(map_path)
    return ScenarioData(scenario, layout, data["train"], data["val"], lines, inputs,
                        horizon_val, found)


def heading_sector(velocity: np.ndarray) -> np.ndarray:
    """Travel direction [W] as the nearest of east/north/west/south (map frame, y up)."""
    angle = np.arctan2(velocity[:, 1], velocity[:, 0])
    return (np.round(angle / (np.pi / 2)).astype(np.int64) % 4)


def eval_windows(val: PairData, cfg: InteractionConfig) -> Windows:
    """Val windows: 1 s observed + n future steps, evenly spaced in each pair."""
    return make_windows(val.trajs, cfg.segment_len, cfg.predict_steps, cfg.eval_windows_per_pair)


def window_labels(windows: Windows, data: PairData) -> dict[str, np.ndarray]:
    """Per-window labels: the generator's labels at the segment end (if known), the pair's
    turn from motion and the robot's last observed travel direction (-1: unknown)."""
    labels = {name: steps[windows.traj_index, windows.end_step]
              for name, steps in data.step_labels.items()}
    labels["robot_turn"] = windows.labels["robot_turn"].astype(np.int64)
    labels["robot_heading"] = heading_sector(windows.actions[:, windows.segment_len - 1, ROBOT])
    return labels
