"""Shortest-path distance to goals around disc obstacles on a plane, on a grid, interpolated.

Shared by the Obstacle world's policy (app/worlds/obstacle.py: its reward's progress) and by
the scene-aware observers (app/worlds/intents.py: the way around the obstacles a person can
see), each with its own grid and blocking.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

# 16 neighbours (knight moves too) keep the grid metric within ~3% of Euclidean, so paths in
# the open are straight rather than axis-or-diagonal
NEIGHBOURS = ((1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2))


class GeodesicFields:
    """Distance [m] to each goal on a grid over [0, width] x [0, height]; a grid node inside a
    disc (x, y, reach) is blocked: an edge touching it is `blocked_factor` times longer."""

    def __init__(self, size_m: tuple[float, float], discs: list[tuple[float, float, float]],
                 goals: list[tuple[float, float]], step_m: float, blocked_factor: float):
        self.step = step_m
        self.nx = int(round(size_m[0] / step_m)) + 1
        self.ny = int(round(size_m[1] / step_m)) + 1
        xs, ys = np.meshgrid(np.arange(self.nx) * step_m, np.arange(self.ny) * step_m)
        nodes = np.stack([xs.ravel(), ys.ravel()], axis=1)
        blocked = np.zeros(len(nodes), dtype=bool)
        for x, y, reach in discs:
            blocked |= np.hypot(nodes[:, 0] - x, nodes[:, 1] - y) < reach
        graph = self._grid_graph(blocked, blocked_factor)
        sources = [self._node(x, y) for x, y in goals]
        dist = dijkstra(graph, directed=False, indices=sources)
        self.values = dist.reshape(len(sources), self.ny, self.nx)

    def _node(self, x: float, y: float) -> int:
        i = int(np.clip(round(x / self.step), 0, self.nx - 1))
        j = int(np.clip(round(y / self.step), 0, self.ny - 1))
        return j * self.nx + i

    def _grid_graph(self, blocked: np.ndarray, blocked_factor: float):
        """16-connected grid; an edge touching a blocked node is `blocked_factor` times longer."""
        index = np.arange(self.nx * self.ny).reshape(self.ny, self.nx)
        rows, cols, weights = [], [], []
        for di, dj in NEIGHBOURS:
            j_lo, j_hi = max(0, -dj), self.ny - max(0, dj)
            i_lo, i_hi = max(0, -di), self.nx - max(0, di)
            src = index[j_lo:j_hi, i_lo:i_hi]
            dst = index[j_lo + dj:j_hi + dj, i_lo + di:i_hi + di]
            src, dst = src.ravel(), dst.ravel()
            length = self.step * np.hypot(di, dj)
            touches = blocked[src] | blocked[dst]
            rows.append(src)
            cols.append(dst)
            weights.append(np.where(touches, length * blocked_factor, length))
        n = self.nx * self.ny
        return coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n, n)).tocsr()

    def distance(self, goal: int, points: np.ndarray) -> np.ndarray:
        """Bilinearly interpolated distance to `goal` at points [..., 2] -> [...]."""
        fx = np.clip(points[..., 0] / self.step, 0, self.nx - 1 - 1e-9)
        fy = np.clip(points[..., 1] / self.step, 0, self.ny - 1 - 1e-9)
        i0, j0 = fx.astype(np.int64), fy.astype(np.int64)
        tx, ty = fx - i0, fy - j0
        v = self.values[goal]
        top = v[j0, i0] * (1 - tx) + v[j0, i0 + 1] * tx
        bottom = v[j0 + 1, i0] * (1 - tx) + v[j0 + 1, i0 + 1] * tx
        return top * (1 - ty) + bottom * ty

    def downhill(self, goal: int, point: np.ndarray) -> np.ndarray:
        """Unit vector [2] along which the distance to `goal` falls fastest at `point`."""
        h = self.step
        offsets = np.array([[h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
        d = self.distance(goal, point[None] + offsets)
        grad = np.array([d[0] - d[1], d[2] - d[3]]) / (2 * h)
        norm = np.linalg.norm(grad)
        return -grad / norm if norm > 1e-9 else np.zeros(2)
