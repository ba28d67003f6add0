"""Training windows cut from two-agent trajectories, and the by-trajectory split.

Shape legend: W windows, T = segment_len, n = n_actions, A = 2 agents (0 robot, 1 human).
- positions [W, T+n+1, A, 2] states s^0..s^{T+n}; s^0..s^T is the segment the encoder sees
- actions   [W, T+n, A, 2]   (s^{i+1} - s^i) / dt, m/s
- encoder features [W, T, 8]: for i = 1..T the state s^i (robot xy, human xy) and the
  action that led into it a^{i-1} (robot v, human v); the segment's T joint steps
- prediction: from s^T, the robot actions a^T..a^{T+n-1}
- reconstruction: from s^t (t random in 0..T-1), the robot actions a^t..a^{t+n-1}
"""

from dataclasses import dataclass

import numpy as np

from app.data.trajectory import ROBOT, TrajectorySet

FEATURES_PER_STEP = 8


@dataclass
class Windows:
    """Fixed-length windows of one TrajectorySet with their trajectory labels."""

    positions: np.ndarray
    traj_index: np.ndarray
    start_step: np.ndarray
    segment_len: int
    n_actions: int
    dt_s: float
    labels: dict[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def actions(self) -> np.ndarray:
        """Velocities [W, T+n, A, 2] from position differences."""
        return (np.diff(self.positions, axis=1) / self.dt_s).astype(np.float32)

    @property
    def end_step(self) -> np.ndarray:
        """Trajectory step of each segment's last state s^T."""
        return self.start_step + self.segment_len

    @property
    def segment_positions(self) -> np.ndarray:
        """The encoder's input states s^0..s^T [W, T+1, A, 2]."""
        return self.positions[:, : self.segment_len + 1]

    @property
    def end_states(self) -> np.ndarray:
        """Joint state s^T at the segment end [W, A, 2]."""
        return self.positions[:, self.segment_len]

    @property
    def pred_targets(self) -> np.ndarray:
        """Robot actions after the segment [W, n, 2]."""
        return self.actions[:, self.segment_len :, ROBOT]

    def recon_pair(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States s^t [W, A, 2] and robot actions a^t..a^{t+n-1} [W, n, 2] for per-window t."""
        rows = np.arange(len(self))
        steps = t[:, None] + np.arange(self.n_actions)[None, :]
        return self.positions[rows, t], self.actions[rows[:, None], steps, ROBOT]


def segment_features(segment_positions: np.ndarray, dt_s: float) -> np.ndarray:
    """Encoder features [.., T, 8] from segment positions [.., T+1, A, 2]."""
    states = segment_positions[..., 1:, :, :]
    actions = (states - segment_positions[..., :-1, :, :]) / dt_s
    lead = states.shape[:-2]
    return np.concatenate([states.reshape(*lead, 4), actions.reshape(*lead, 4)],
                          axis=-1, dtype=np.float32)


def evenly_spaced_starts(length: int, span: int, count: int) -> np.ndarray:
    """Up to `count` evenly spaced start steps whose window of `span` actions fits in `length`."""
    last = length - span
    if last < 0:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.linspace(0, last, min(count, last + 1)).round().astype(np.int64))


def make_windows(trajs: TrajectorySet, segment_len: int, n_actions: int,
                 per_trajectory: int, index: np.ndarray | None = None) -> Windows:
    """Cut evenly spaced windows from the trajectories at `index` (default: all)."""
    index = np.arange(len(trajs)) if index is None else np.asarray(index)
    span = segment_len + n_actions
    traj_rows, starts = [], []
    for row in index:
        found = evenly_spaced_starts(int(trajs.lengths[row]), span, per_trajectory)
        traj_rows.append(np.full(len(found), row, dtype=np.int64))
        starts.append(found)
    traj_index = np.concatenate(traj_rows) if traj_rows else np.zeros(0, np.int64)
    start_step = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    steps = start_step[:, None] + np.arange(span + 1)[None, :]
    return Windows(
        positions=trajs.positions[traj_index[:, None], steps].astype(np.float32),
        traj_index=traj_index, start_step=start_step, segment_len=segment_len,
        n_actions=n_actions, dt_s=trajs.dt_s,
        labels={name: values[traj_index] for name, values in trajs.labels.items()},
    )


def split_by_trajectory(n: int, val_fraction: float, test_fraction: float,
                        seed: int, held_out: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Disjoint sorted trajectory indices for train/val/test (never split by window).

    With `held_out` (a recorded world's [n] bool: cut from held-out recordings) those are the
    test split and the validation split is drawn from the rest, so no recording the bank's
    trials come from is ever trained on."""
    if held_out is not None:
        return _split_around(np.asarray(held_out, dtype=bool), val_fraction, seed)
    order = np.random.default_rng(seed).permutation(n)
    n_test = max(1, round(n * test_fraction)) if n >= 3 else 0
    n_val = max(1, round(n * val_fraction)) if n >= 3 else 0
    return {"test": np.sort(order[:n_test]), "val": np.sort(order[n_test:n_test + n_val]),
            "train": np.sort(order[n_test + n_val:])}


def _split_around(held_out: np.ndarray, val_fraction: float, seed: int) -> dict[str, np.ndarray]:
    rest = np.random.default_rng(seed).permutation(np.flatnonzero(~held_out))
    n_val = max(1, round(len(held_out) * val_fraction)) if len(rest) >= 2 else 0
    return {"test": np.flatnonzero(held_out), "val": np.sort(rest[:n_val]),
            "train": np.sort(rest[n_val:])}
