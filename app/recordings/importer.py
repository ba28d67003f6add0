"""`tomstudy import-recordings`: a recorded world's recordings -> its trajectory file.

The recorded world's counterpart of `simulate`: read and validate every recording of the
config's source (a format error names file, line and column), cut robot/human pairs over
fixed windows (app/recordings/pairs.py), drop the pairs whose two agents' centres ever come
closer than the mean of their two widths (side by side, touching: tracking errors, or the
generator's cars passing through each other: no clip may show two cars on top of each other;
meta.json counts them), sample them every `dt_s`, keep each agent's recorded length and width
(the config's `agent:` where a recording gives none), label each pair with the
robot's and the human's turn over the window, mark the pairs of held-out recordings (every
checkpoint's test split, so the bank's trials come from recordings no model trained on),
and write data/<world>/trajectories.npz and meta.json. Everything is read and checked before
anything is written, so a malformed recording leaves the data dir as it was.

meta.json names every input file with its SHA-256 and leaves out the wall time: a
checkpoint's content hash covers this file, and the same recordings must give the same
checkpoints on any machine.
"""

import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

import app
from app.core.files import sha256_file, write_json
from app.data.trajectory import Episode, TrajectorySet
from app.layout import Layout
from app.recordings import pairs as px
from app.recordings import tracks as tx
from app.recordings.config import CsvSource, InteractionSource, RecordedConfig
from app.recordings.lanelet_map import LaneLine, MapError, read_lanelet_map
from app.recordings.pairs import TURN_NAMES, turn_label
from app.recordings.scene import SceneFrame, frame_around, recorded_scene

LABEL_NAMES = {"robot_turn": TURN_NAMES, "human_turn": TURN_NAMES}
ROBOT_LABEL = "robot_turn"
MIN_PAIRS = 3  # per split: a test split and the trainer's train and validation splits


class UnusableRecordings(ValueError):
    """The recordings cannot make this world; the message says why and what to change."""


# what reading a recorded world's sources may raise: each names the file (and line, column)
RECORDING_ERRORS = (tx.TrackFileError, MapError, UnusableRecordings)


@dataclass
class Recordings:
    """What a source gives: its recordings, their time step, which frames are held out,
    the pairing rule, its files (name -> sha256) and the lines to draw."""

    source: str
    recordings: list[tx.Recording]
    frame_dt_s: float
    ranges: dict[str, dict[str, tuple[int, int]]]  # split -> recording -> frame range
    rule: px.PairRule = px.CARS  # which agent types are robot and human (pairs.py)
    files: dict[str, str] = field(default_factory=dict)
    lines: list[LaneLine] = field(default_factory=list)


@dataclass
class ImportResult:
    """Where the trajectories went and what they hold."""

    npz_path: Path
    meta: dict


def recordings_path(path: str, layout: Layout) -> Path:
    """A path a recorded world's config gives: absolute as given, else under the recordings dir."""
    path = Path(path).expanduser()
    return path if path.is_absolute() else layout.recordings() / path


def read_source(config: RecordedConfig, layout: Layout) -> Recordings:
    """Read and validate the config's recordings (TrackFileError / RecordingError on bad files)."""
    root = recordings_path(config.source.path, layout)
    if not root.exists():
        hint = (" (no data yet? `tomstudy generate-recordings` writes GENERATED, not real, "
                "INTERACTION files there)") if isinstance(config.source, InteractionSource) else ""
        raise UnusableRecordings(f"source.path: {root} does not exist; put the recordings there "
                                 f"(the recordings dir is {layout.recordings()}, set by "
                                 f"TOMSTUDY_RECORDINGS_DIR) or fix the world config{hint}")
    if isinstance(config.source, InteractionSource):
        return interaction_recordings(root, config.source)
    lines = recordings_path(config.source.lines, layout) if config.source.lines else None
    return csv_recordings(root, config.source, lines)


def interaction_recordings(root: Path, source: InteractionSource) -> Recordings:
    """An INTERACTION scenario: v1.2's val cases held out, or v1.0's listed / last frames."""
    layout = tx.detect_layout(root, source.scenario)
    files = tx.split_files(root, source.scenario, layout)
    if layout == "v1.2":
        train, val = (tx.load_recordings(files[s]) for s in tx.SPLITS)
        ranges = {"train": whole(train), "val": whole(val)}
        recordings = train + val
    else:
        recordings = tx.load_recordings(files["train"])
        ranges = px.v10_split(root, source.scenario, recordings, 1 - source.held_out_fraction,
                              source.validation_list == "use",
                              "source.validation_list: ignore in the world's config")
    inputs = sorted({f for fs in files.values() for f in fs})
    map_path = root / "maps" / f"{source.scenario}.osm"
    lines = []
    if map_path.is_file():
        lines = read_lanelet_map(map_path)
        inputs.append(map_path)
    return Recordings(f"INTERACTION {source.scenario} ({layout})", recordings,
                      tx.FRAME_MS / 1000, ranges, px.CARS, hashes(inputs, root), lines)


def csv_recordings(root: Path, source: CsvSource, line_path: Path | None) -> Recordings:
    """A lab's CSV logs: robot-role agents paired with the nearest human-role agent; the lines
    to draw from `line_path` (outside a folder of logs, whose every .csv is read as logs)."""
    from app.recordings.csv_logs import read_line_file, read_logs

    logs = read_logs(root)
    names = sorted(r.name for r in logs.recordings)
    if len(names) == 1:
        ranges = px.time_split(logs.recordings, 1 - source.held_out_fraction)
    else:
        count = max(1, round(len(names) * source.held_out_fraction))
        held = {names[int(k)] for k in np.linspace(len(names) - 1, 0, count).round()}
        ranges = px.recording_split(logs.recordings, sorted(held))
    files = dict(logs.files)
    lines = []
    if line_path is not None:
        lines = read_line_file(line_path)
        files.update(hashes([line_path], line_path.parent))
    return Recordings(f"CSV logs {root.name}", logs.recordings, logs.dt_s, ranges,
                      px.ROLES, files, lines)


def whole(recordings: list[tx.Recording]) -> dict[str, tuple[int, int]]:
    """Every frame of each recording."""
    return {r.name: (min(int(t.frames[0]) for t in r.tracks),
                     max(int(t.frames[-1]) for t in r.tracks)) for r in recordings}


def hashes(paths: list[Path], root: Path) -> dict[str, str]:
    """Each file's SHA-256, named relative to the folder `root` (the lab's folders are its own
    business)."""
    return {Path(p).relative_to(root).as_posix(): sha256_file(p) for p in paths}


# ---------------------------------------------------------------- pairs


def frames_per(seconds: float, frame_dt_s: float, name: str) -> int:
    """How many recording frames `seconds` spans; UnusableRecordings if not a whole number."""
    frames = seconds / frame_dt_s
    if abs(frames - round(frames)) > 1e-6 * max(1.0, frames) or round(frames) < 1:
        raise UnusableRecordings(f"{name}: {seconds:g} s is not a whole number of the recordings' "
                           f"{frame_dt_s:g} s steps")
    return int(round(frames))


def split_pairs(rec: Recordings, config: RecordedConfig) -> tuple[dict[str, list[px.Pair]],
                                                                  dict[str, int]]:
    """The pairs of each split ('train', 'val' = held out) whose agents never overlap, evenly
    thinned to `max_pairs`; and how many overlapping pairs each split dropped."""
    size = frames_per(config.window_s, rec.frame_dt_s, "window_s")
    stride = frames_per(config.window_stride_s, rec.frame_dt_s, "window_stride_s")
    out, dropped = {}, {}
    for split in tx.SPLITS:
        chosen = [r for r in rec.recordings if r.name in rec.ranges[split]]
        found = px.extract_pairs(chosen, size, stride, config.pair_max_distance_m,
                                 rec.ranges[split], rec.rule)
        pairs = [p for p in found
                 if closest_m(p) >= agent_sizes(p, config)[:, 1].mean()]
        dropped[split] = len(found) - len(pairs)
        if 0 < config.max_pairs < len(pairs):
            keep = np.linspace(0, len(pairs) - 1, config.max_pairs).round().astype(int)
            pairs = [pairs[k] for k in keep]
        if len(pairs) < MIN_PAIRS:
            what = "held-out" if split == "val" else "training"
            raise UnusableRecordings(
                f"{rec.source}: only {len(pairs)} {what} pairs (a robot and a human both "
                f"present for {config.window_s:g} s, within {config.pair_max_distance_m:g} m "
                f"at some step); need {MIN_PAIRS}: record more, or shorten window_s")
        out[split] = pairs
    return out, dropped


def closest_m(pair: px.Pair) -> float:
    """The smallest distance between the robot's and the human's centres over the pair [m]."""
    gaps = pair.positions[:, 0] - pair.positions[:, 1]
    return float(np.hypot(gaps[:, 0], gaps[:, 1]).min())


def agent_sizes(pair: px.Pair, config: RecordedConfig) -> np.ndarray:
    """The pair's two (length, width) [2, 2] m as recorded, the config's `agent:` where a
    recording gives none (a lab's logs without the size columns)."""
    fallback = np.array([config.agent.length_m, config.agent.width_m])
    return np.where(np.isfinite(pair.sizes), pair.sizes, fallback)


def pair_episode(pair: px.Pair, step: int, frame: SceneFrame,
                 config: RecordedConfig) -> Episode:
    """A pair sampled every `step` frames, labelled, sized, in the scene frame."""
    threshold_deg = config.turn_threshold_deg
    labels = {"robot_turn": turn_label(pair.positions[:, 0], threshold_deg),
              "human_turn": turn_label(pair.positions[:, 1], threshold_deg)}
    return Episode(frame.points(pair.positions[::step]),
                   frame.headings(pair.headings[::step]), pair.speeds[::step].copy(), labels,
                   agent_sizes(pair, config))


def driven_points(rec: Recordings) -> np.ndarray:
    """Every position of every agent the pairing rule may pick, map frame [M, 2]."""
    xy = [t.xy for r in rec.recordings for t in r.tracks if rec.rule.takes(t)]
    return np.concatenate(xy) if xy else np.zeros((0, 2))


# ---------------------------------------------------------------- the world's data


def build_trajectories(world: str, config: RecordedConfig,
                       rec: Recordings) -> tuple[TrajectorySet, dict]:
    """The world's trajectories (training pairs first, then held-out) and their counts."""
    step = frames_per(config.dt_s, rec.frame_dt_s, "dt_s")
    pairs, overlapping = split_pairs(rec, config)
    every = pairs["train"] + pairs["val"]
    frame = frame_around(np.concatenate([p.positions.reshape(-1, 2) for p in every]))
    episodes = [pair_episode(p, step, frame, config)
                for p in tqdm(every, desc=f"pairs {world}", unit="pair", leave=False)]
    scene = recorded_scene(world, config, rec.source, frame,
                           np.concatenate([e.positions.reshape(-1, 2) for e in episodes]),
                           frame.points(driven_points(rec)), rec.lines)
    held_out = np.arange(len(every)) >= len(pairs["train"])
    trajs = TrajectorySet.from_episodes(world, config.dt_s, episodes, LABEL_NAMES, scene,
                                        held_out)
    counts = {"recordings": {s: sum(hi >= lo for lo, hi in rec.ranges[s].values())
                             for s in tx.SPLITS},
              "pairs": {"train": len(pairs["train"]), "held_out": len(pairs["val"])},
              "pairs_dropped_overlapping": {"train": overlapping["train"],
                                            "held_out": overlapping["val"]}}
    return trajs, counts


def import_recordings(world: str, config: RecordedConfig, layout: Layout) -> ImportResult:
    """Read the world's recordings and write its trajectories and meta.json."""
    rec = read_source(config, layout)
    trajs, counts = build_trajectories(world, config, rec)
    npz_path, meta_path = layout.trajectories(world), layout.trajectories_meta(world)
    trajs.save(npz_path)
    meta = {"world": world, "kind": "recorded", "config": config.model_dump(),
            "source": rec.source, "input_sha256": rec.files, "frame_dt_s": rec.frame_dt_s,
            "dt_s": config.dt_s, "n": len(trajs), **counts,
            "max_steps": int(trajs.positions.shape[1] - 1),
            "mean_length_steps": float(trajs.lengths.mean()),
            "label_counts": trajs.label_counts(), "frame": trajs.scene.frame,
            "package_version": app.__version__, "python": platform.python_version(),
            "numpy": np.__version__, "content_sha256": sha256_file(npz_path)}
    write_json(meta_path, meta)
    return ImportResult(npz_path, meta)

