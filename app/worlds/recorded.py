"""Recorded worlds: two-agent interactions read from recordings, not simulated.

The same `World` the bank, the observers and the display check read, from a recording set
(app/recordings/: the config, the import, the scene). What the simulated worlds get from a
model of their agents, a recorded world takes from the data:
- its starts are recorded states (`starts_as_recorded`): a start drawn from the data keeps
  that recorded car's heading and speed, and the bank's `policy_actions` there (the precise
  observers' answer) are that car's recorded next moves; from the robot's own segment end,
  what really happened next (app/bank/start_states.py);
- `robot_policy_actions` answers any other state: the recorded robot state nearest it within
  `policy_radius_m` whose heading is within `start_heading_tolerance_deg` of its own, and
  that state's next moves; with none, the state's heading and speed held;
- a segment may end where the robot is under way: moving at least `min_moving_speed_mps`
  over the step into the end and the next ones (a standing car's move cannot be clicked);
- start states lie where recorded robots drove the way this robot is heading (`near`: within
  the reach of the n steps, `far`: up to twice that), clear of the human by the two cars'
  lengths (the scene's `agents`, at this segment's recorded sizes: TrajectorySet.scene_of).
"""

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from app.configio import load_yaml_model
from app.data.scene import Scene
from app.data.trajectory import HUMAN, ROBOT, Covered, TrajectorySet, wrap_angle
from app.layout import Layout
from app.recordings.config import RecordedConfig
from app.recordings.importer import LABEL_NAMES, ROBOT_LABEL, ImportResult, import_recordings

MOVING_CHECK_STEPS = 3  # steps after a segment's end that must move too


class NotImported(RuntimeError):
    """A recorded world's data is asked for before its recordings were imported."""


def angle_gap(a: np.ndarray, b: float) -> np.ndarray:
    """|a - b| wrapped into [0, pi] (rad)."""
    return np.abs(wrap_angle(np.asarray(a) - b))


class RecordedWorld:
    """A world whose trajectories are imported recordings (app/recordings/importer.py)."""

    label_names = LABEL_NAMES
    robot_label = ROBOT_LABEL
    starts_as_recorded = True

    def __init__(self, name: str, config: RecordedConfig) -> None:
        self.name = name
        self.config = config
        self.dt_s = config.dt_s
        self._futures: _RecordedFutures | None = None

    @classmethod
    def from_yaml(cls, name: str, path: Path) -> "RecordedWorld":
        """The world named `name` from its YAML config."""
        return cls(name, load_yaml_model(path, RecordedConfig))

    def import_recordings(self, layout: Layout) -> ImportResult:
        """Read this world's recordings into its trajectory file (the `simulate` step)."""
        return import_recordings(self.name, self.config, layout)

    def prepare(self, layout: Layout) -> None:
        """Index the imported recordings' robot states and futures (NotImported if missing)."""
        path = layout.trajectories(self.name)
        if not path.is_file():
            raise NotImported(f"{path}: no trajectories; run `tomstudy import-recordings "
                              f"{self.name}`")
        self._futures = _RecordedFutures(TrajectorySet.load(path))

    def robot_policy_actions(self, positions: np.ndarray, robot_heading: float,
                             robot_speed: float, human_velocity: np.ndarray, labels: dict,
                             n_steps: int, rng: np.random.Generator) -> np.ndarray:
        """What a recorded robot did next from this start [n_steps, 2] (module docstring)."""
        if self._futures is None:
            raise NotImported(f"{self.name}: prepare(layout) reads the recordings first")
        found = self._futures.nearest(np.asarray(positions[0], dtype=np.float64), robot_heading,
                                      n_steps, self.config.policy_radius_m,
                                      np.radians(self.config.start_heading_tolerance_deg))
        if found is not None:
            return found
        held = robot_speed * np.array([np.cos(robot_heading), np.sin(robot_heading)])
        return np.repeat(held[None], n_steps, axis=0)

    def visible_ends(self, robot_track: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Ends where the robot moves at least min_moving_speed_mps into the end and over the
        next MOVING_CHECK_STEPS steps (as far as the track goes)."""
        speeds = np.linalg.norm(np.diff(robot_track, axis=0), axis=1) / self.dt_s
        slow = speeds < self.config.min_moving_speed_mps
        keep = [not slow[max(end - 1, 0): end + MOVING_CHECK_STEPS].any() for end in ends]
        return ends[np.asarray(keep, dtype=bool)] if len(ends) else ends

    def data_start_candidates(self, scene: Scene, segment: np.ndarray, covered: Covered,
                              reach: float) -> dict[str, np.ndarray]:
        """`near` (within `reach`) and `far` (`reach` to 2 `reach`) recorded robot states
        (indices into `covered`) heading the robot's way, clear of the human, with `reach` of
        scene around them."""
        robot, human = segment[-1, ROBOT], segment[-1, HUMAN]
        move = segment[-1, ROBOT] - segment[-2, ROBOT]
        heading = float(np.arctan2(move[1], move[0]))
        pts = covered.positions
        dist = np.linalg.norm(pts - robot, axis=1)
        clearance = sum(a.length_m for a in scene.agents)  # the robot's and the human's
        b = scene.bounds
        keep = ((dist <= 2 * reach)
                & (angle_gap(covered.headings, heading)
                   <= np.radians(self.config.start_heading_tolerance_deg))
                & (np.linalg.norm(pts - human, axis=1) > clearance)
                & (pts[:, 0] - reach > b.x_min_m) & (pts[:, 0] + reach < b.x_max_m)
                & (pts[:, 1] - reach > b.y_min_m) & (pts[:, 1] + reach < b.y_max_m))
        return {"near": np.flatnonzero(keep & (dist <= reach)),
                "far": np.flatnonzero(keep & (dist > reach))}


class _RecordedFutures:
    """Every recorded robot state with its next moves, for nearest-state look-ups."""

    def __init__(self, trajs: TrajectorySet) -> None:
        self.trajs = trajs
        index, steps = [], []
        for i, length in enumerate(trajs.lengths):
            index.append(np.full(int(length) + 1, i))
            steps.append(np.arange(int(length) + 1))
        self.index, self.step = np.concatenate(index), np.concatenate(steps)
        positions = trajs.positions[self.index, self.step, ROBOT].astype(np.float64)
        self.headings = trajs.headings[self.index, self.step, ROBOT].astype(np.float64)
        self.tree = cKDTree(positions)
        self.positions = positions

    def nearest(self, point: np.ndarray, heading: float, n_steps: int, radius: float,
                tolerance: float) -> np.ndarray | None:
        """The next n actions [n, 2] of the nearest state within `radius` heading within
        `tolerance` that has n recorded steps after it; None if there is none."""
        near = np.asarray(self.tree.query_ball_point(point, radius), dtype=np.int64)
        if not len(near):
            return None
        lengths = self.trajs.lengths[self.index[near]]
        near = near[(angle_gap(self.headings[near], heading) <= tolerance)
                    & (self.step[near] + n_steps <= lengths)]
        if not len(near):
            return None
        best = near[np.argmin(np.linalg.norm(self.positions[near] - point, axis=1))]
        i, s = self.index[best], self.step[best]
        track = self.trajs.positions[i, s: s + n_steps + 1, ROBOT].astype(np.float64)
        return np.diff(track, axis=0) / self.trajs.dt_s
