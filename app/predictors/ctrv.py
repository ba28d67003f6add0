"""Constant turn rate and velocity (CTRV): a plug-in predictor, registered like a lab's own.

It ships with tomstudy but reaches a study only as any plug-in does: through the entry point
`ctrv = "app.predictors.ctrv:CTRV"` in the group `tomstudy.predictors` (pyproject.toml) and a
study config's `predictors: [ctrv]`.

From the robot's last `history_steps` steps of the history it takes the speed (the mean step
length over dt) and the turn rate (the mean change of direction between consecutive steps that
both move, over dt), and rolls them forward from each start state, starting from that start's
robot heading: step j moves at that speed in the direction heading + turn * dt * (j + 1/2),
which is exactly the chord of a circular arc driven at a constant turn rate (so a robot that
drove a circle is predicted to go on along it, and one that drove straight at its heading is
predicted by constant velocity). Headings are the world's drawing headings: where a world's
positions are in a moving frame (Highway's camera frame) the on-screen direction of travel
differs from the heading, and CTRV there starts from the car's heading, not its on-screen
direction.
"""

from dataclasses import dataclass

import numpy as np

from app.core.alignment import ZERO_SPEED_MPS
from app.data.trajectory import ROBOT, wrap_angle
from app.predictors.protocol import PredictorAnswer, code_hash


def speed_and_turn(track: np.ndarray, dt_s: float, steps: int) -> tuple[float, float]:
    """Mean speed [m/s] and turn rate [rad/s] of a track [T+1, 2] over its last `steps` steps
    (no turn where fewer than two consecutive steps move)."""
    moves = np.diff(track, axis=0)[-steps:]
    speeds = np.hypot(moves[:, 0], moves[:, 1]) / dt_s
    directions = np.arctan2(moves[:, 1], moves[:, 0])
    both_move = (speeds[1:] > ZERO_SPEED_MPS) & (speeds[:-1] > ZERO_SPEED_MPS)
    turns = wrap_angle(np.diff(directions))[both_move]
    turn_rate = float(turns.mean()) / dt_s if len(turns) else 0.0
    return float(speeds.mean()), turn_rate


def roll_forward(headings: np.ndarray, speed: float, turn_rate: float, dt_s: float,
                 n_steps: int) -> np.ndarray:
    """Actions [K, n, 2] (m/s): from each heading, n steps at `speed` turning at `turn_rate`."""
    directions = headings[:, None] + turn_rate * dt_s * (np.arange(n_steps) + 0.5)[None, :]
    return speed * np.stack([np.cos(directions), np.sin(directions)], axis=-1)


@dataclass(frozen=True)
class CTRV:
    """Constant turn rate and velocity from the robot's last `history_steps` steps."""

    name: str = "ctrv"
    version: str = "1"
    history_steps: int = 4

    @property
    def content_hash(self) -> str:
        """sha256 of the name, version and history_steps."""
        return code_hash(self.name, self.version, {"history_steps": self.history_steps})

    def answer(self, history: np.ndarray, starts: np.ndarray, headings: np.ndarray,
               dt_s: float, n_steps: int) -> PredictorAnswer:
        """The history's speed and turn rate, rolled forward from every start's heading."""
        speed, turn_rate = speed_and_turn(history[:, ROBOT], dt_s, self.history_steps)
        return PredictorAnswer(roll_forward(headings, speed, turn_rate, dt_s, n_steps))
