"""Robot/human pairs cut from recordings (INTERACTION or a lab's logs), and train/val ranges.

Pair rule (one pair per robot and window): every agent of a robot type (`PairRule.robots`)
present at every frame of the window is a robot; its human is the other agent of a human
type (`PairRule.humans`) present at every frame of the window with the smallest mean
distance to the robot, provided the two come within `max_distance_m` of each other at some
frame. Other agent types are never robot or human. `CARS` (the default, INTERACTION): cars
for both, so pedestrians and bicycles are never paired; `ROLES` (a lab's logs): each
`robot`-role agent with its nearest `human`-role agent.
"""

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from app.data.trajectory import Episode
from app.recordings import tracks as tx
from app.recordings.tracks import CAR_TYPES, Recording, Track

TURN_NAMES = ["left", "straight", "right"]  # a track's turn label, index = turn_label

@dataclass(frozen=True)
class PairRule:
    """Which agent types may be the robot of a pair and which its human."""

    robots: frozenset[str]
    humans: frozenset[str]

    def takes(self, track: Track) -> bool:
        """True if the track may be robot or human under this rule."""
        return track.agent_type in self.robots or track.agent_type in self.humans


CARS = PairRule(robots=CAR_TYPES, humans=CAR_TYPES)
ROLES = PairRule(robots=frozenset({"robot"}), humans=frozenset({"human"}))


@dataclass
class Pair:
    """A robot and its human over one window of consecutive frames."""

    recording: str
    robot_id: int
    human_id: int
    first_frame: int
    positions: np.ndarray  # [W, 2 agents, 2] m
    headings: np.ndarray  # [W, 2] rad
    speeds: np.ndarray  # [W, 2] m/s, from the recorded vx, vy
    sizes: np.ndarray  # [2 agents, 2] m (length, width) as recorded; NaN where not given

    def episode(self, step: int, labels: dict[str, int] | None = None) -> Episode:
        """This pair as an Episode sampled every `step` frames."""
        return Episode(self.positions[::step].copy(), self.headings[::step].copy(),
                       self.speeds[::step].copy(), labels or {}, self.sizes.copy())


def _window_states(track: Track, first: int, size: int) -> tuple[np.ndarray, ...] | None:
    """(xy [W,2], heading [W], speed [W]) if the track is present at all W frames, else None."""
    start = int(np.searchsorted(track.frames, first))
    stop = start + size
    if stop > len(track.frames) or track.frames[start] != first:
        return None
    if track.frames[stop - 1] != first + size - 1:
        return None  # a gap inside the window
    v = track.v[start:stop]
    psi = track.psi[start:stop]
    heading = np.where(np.isfinite(psi), psi, np.arctan2(v[:, 1], v[:, 0]))
    return track.xy[start:stop], heading, np.hypot(v[:, 0], v[:, 1])


def window_first_frames(recording: Recording, size: int, stride: int,
                        frame_range: tuple[int, int] | None = None,
                        rule: PairRule = CARS) -> list[int]:
    """First frames of the windows of `size` frames, every `stride` frames, inside the range."""
    agents = [t for t in recording.tracks if rule.takes(t)]
    if not agents:
        return []
    lo = min(int(t.frames[0]) for t in agents)
    hi = max(int(t.frames[-1]) for t in agents)
    if frame_range is not None:
        lo, hi = max(lo, frame_range[0]), min(hi, frame_range[1])
    return list(range(lo, hi - size + 2, stride))


def pairs_in_window(recording: Recording, first: int, size: int, max_distance_m: float,
                    rule: PairRule = CARS) -> list[Pair]:
    """Every robot present over the window paired with its nearest interacting human (above)."""
    present, last = [], first + size - 1
    for track in recording.tracks:
        if rule.takes(track) and track.frames[0] <= first and track.frames[-1] >= last:
            states = _window_states(track, first, size)
            if states is not None:
                present.append((track, states))
    if len(present) < 2:
        return []
    xy = np.stack([s[0] for _, s in present])  # [C, W, 2]
    dist = np.linalg.norm(xy[:, None] - xy[None, :], axis=-1)  # [C, C, W]
    mean = dist.mean(axis=-1)
    mean[dist.min(axis=-1) > max_distance_m] = np.inf
    np.fill_diagonal(mean, np.inf)
    mean[:, [t.agent_type not in rule.humans for t, _ in present]] = np.inf
    pairs = []
    for r, (robot, r_states) in enumerate(present):
        if robot.agent_type not in rule.robots:
            continue
        h = int(np.argmin(mean[r]))
        if not np.isfinite(mean[r, h]):
            continue
        human, h_states = present[h]
        pairs.append(Pair(
            recording=recording.name, robot_id=robot.track_id, human_id=human.track_id,
            first_frame=first,
            positions=np.stack([r_states[0], h_states[0]], axis=1),
            headings=np.stack([r_states[1], h_states[1]], axis=1),
            speeds=np.stack([r_states[2], h_states[2]], axis=1),
            sizes=np.array([[robot.length_m, robot.width_m], [human.length_m, human.width_m]],
                           dtype=np.float64)))
    return pairs


def extract_pairs(recordings: list[Recording], size: int, stride: int, max_distance_m: float,
                  frame_ranges: dict[str, tuple[int, int]] | None = None,
                  rule: PairRule = CARS) -> list[Pair]:
    """All pairs of all windows of all recordings, in a deterministic order."""
    pairs = []
    for rec in tqdm(sorted(recordings, key=lambda r: r.name), desc="pairs", unit="recording",
                    leave=False):
        span = (frame_ranges or {}).get(rec.name)
        for first in window_first_frames(rec, size, stride, span, rule):
            pairs.extend(pairs_in_window(rec, first, size, max_distance_m, rule))
    return pairs


# ---------------------------------------------------------------- train / val frame ranges


def recording_split(recordings: list[Recording], val_names: list[str]) -> dict[str, dict]:
    """Whole recordings to train or val (by name); the frame ranges `extract_pairs` takes."""
    ranges: dict[str, dict] = {"train": {}, "val": {}}
    for rec in recordings:
        frames = np.concatenate([t.frames for t in rec.tracks])
        split = "val" if rec.name in val_names else "train"
        ranges[split][rec.name] = (int(frames.min()), int(frames.max()))
        ranges["val" if split == "train" else "train"][rec.name] = (0, -1)
    return ranges


def v10_split(data_dir, scenario: str, recordings: list[Recording], train_fraction: float,
              use_list: bool, switch: str) -> dict[str, dict]:
    """v1.0's ranges: the recordings on the devkit's validation list held out whole (unless
    `use_list` is off), else each recording's last 1 - train_fraction; PartialDownload if the
    list names recordings the copy lacks (`switch` names the config key that ignores it)."""
    listed = tx.official_val_recordings(data_dir, scenario) if use_list else []
    present = [r.name for r in recordings]
    tx.check_listed_present(data_dir, scenario, listed, present, switch)
    if listed and set(present) - set(listed):
        return recording_split(recordings, listed)
    return time_split(recordings, train_fraction)


def time_split(recordings: list[Recording], train_fraction: float) -> dict[str, dict]:
    """v1.0 has no val split: per recording, frames before the cut are train, after are val."""
    ranges: dict[str, dict] = {"train": {}, "val": {}}
    for rec in recordings:
        frames = np.concatenate([t.frames for t in rec.tracks])
        lo, hi = int(frames.min()), int(frames.max())
        cut = lo + int(round((hi - lo + 1) * train_fraction))
        ranges["train"][rec.name] = (lo, cut - 1)
        ranges["val"][rec.name] = (cut, hi)
    return ranges


def turn_label(track: np.ndarray, threshold_deg: float) -> int:
    """Index into TURN_NAMES of a map-frame track's [W, 2] travel direction change over its
    moving steps (a map's y points up, so a positive change is a left turn)."""
    moves = np.diff(track, axis=0)
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
