"""Attention-check start states shared by the worlds: points a step or so beside or behind the
robot's segment end, in free space, from which "it keeps doing what it was doing" stays in view.

Shape legend: A = 2 agents (0 robot, 1 human); a segment is [T+1, A, 2] states [m].
"""

import numpy as np

from app.data.scene import Scene
from app.data.trajectory import HUMAN, ROBOT


def heading_unit(segment: np.ndarray) -> np.ndarray:
    """Unit vector of the robot's last segment move."""
    motion = segment[-1, ROBOT] - segment[-2, ROBOT]
    return motion / (np.linalg.norm(motion) + 1e-12)


def offset_points(scene: Scene, segment: np.ndarray, max_step: float,
                  n_steps: int) -> np.ndarray:
    """Points [P, 2] 0.5-1 step beside or behind the robot's segment end, inside the view,
    clear of obstacles and of the human."""
    robot = segment[-1, ROBOT]
    ahead = heading_unit(segment)
    side = np.array([-ahead[1], ahead[0]])
    offsets = [a * ahead + b * side for a in (-1.0, -0.5, 0.0) for b in (-1.0, -0.5, 0.5, 1.0)]
    pts = robot + max_step * np.array(offsets + [-ahead, -0.5 * ahead])
    b = scene.bounds
    ends = pts + n_steps * max_step * ahead  # the obvious continuation must stay in view
    keep = np.ones(len(pts), dtype=bool)
    for p in (pts, ends):
        keep &= (p[:, 0] > b.x_min_m) & (p[:, 0] < b.x_max_m) \
            & (p[:, 1] > b.y_min_m) & (p[:, 1] < b.y_max_m)
    for c in scene.obstacles:
        keep &= np.hypot(pts[:, 0] - c.x_m, pts[:, 1] - c.y_m) > c.radius_m + 0.3
    human = segment[-1, HUMAN]
    keep &= np.linalg.norm(pts - human, axis=1) > 2 * max(a.width_m for a in scene.agents)
    return pts[keep]
