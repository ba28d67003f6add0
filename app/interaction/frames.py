"""The frame of the models' positions: the map's (`absolute`) or the human car's.

`human_relative` is "from the other car's point of view": every position of a window, the
robot's and the human's, minus the human car's position at the window's last observed step
s^T, the moment the robot's next action is predicted. It translates and does not rotate
(docs/reproduce/interaction.md says why). Actions are differences of positions, so velocities -- the
encoder's velocity inputs, the predicted and the true next actions, constant velocity --
are the same in both frames: only the positions the models see change.

Training in this frame passes `in_frame` to the trainer as its window transform, so the
split, the normaliser and the fit are the trainer's own.
"""

from dataclasses import replace
from typing import Literal

import numpy as np

from app.data.trajectory import HUMAN
from app.data.windows import Windows

Frame = Literal["absolute", "human_relative"]
FRAMES: tuple[Frame, ...] = ("absolute", "human_relative")


def human_origin(positions: np.ndarray, anchor_step: int) -> np.ndarray:
    """The human car's position [W, 2] at `anchor_step` of windows [W, S, A, 2]."""
    return np.asarray(positions, dtype=np.float64)[:, anchor_step, HUMAN]


def to_human_relative(positions: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Positions [W, S, A, 2] minus each window's origin [W, 2] (float64)."""
    return np.asarray(positions, dtype=np.float64) - origin[:, None, None, :]


def from_human_relative(relative: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The inverse of `to_human_relative`: back to map positions (float64)."""
    return np.asarray(relative, dtype=np.float64) + origin[:, None, None, :]


def in_frame(windows: Windows, frame: Frame) -> Windows:
    """The windows with positions in `frame` (the same object for `absolute`)."""
    if frame == "absolute":
        return windows
    if frame != "human_relative":
        raise ValueError(f"unknown frame {frame!r}; choose one of {', '.join(FRAMES)}")
    origin = human_origin(windows.positions, windows.segment_len)
    moved = to_human_relative(windows.positions, origin).astype(np.float32)
    return replace(windows, positions=moved)
