"""A recorded world's scene: its frame, bounds, the map's lines and the area recorded agents drove.

Frame: the recordings' planar x, y (y up, as on a map) moved to the middle of the pairs'
box and mirrored in y, since the browser and the plots draw y downwards: scene x = x - cx,
scene y = cy - y. A map's left turn is then a left turn on screen; headings change sign.
"""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from app.data.scene import (
    HUMAN_COLOR,
    ROBOT_COLOR,
    AgentShape,
    Bounds,
    DrivenArea,
    Polyline,
    RecordedScene,
    Scene,
)
from app.recordings.config import RecordedConfig
from app.recordings.lanelet_map import LaneLine

LINE_DECIMALS = 2  # lines are drawn, never scored: centimetres are plenty
SIMPLIFY_M = 0.15  # a line point this close to the straight line through its neighbours goes
# lanelet2 line types -> how the browser draws them (other types, e.g. traffic signs, are left
# out). A `virtual` way is a lanelet's border where nothing is painted (across a junction, at a
# lane's start): it is read but never drawn, so every line on screen is paint or a kerb, as
# the world intros say; a crossing's markings are paint.
LINE_KINDS = {"curbstone": "kerb", "road_border": "kerb", "guard_rail": "kerb", "fence": "kerb",
              "wall": "kerb", "line_thin": "border", "line_thick": "border",
              "virtual": None, "pedestrian_marking": "border", "zebra_marking": "border",
              "stop_line": "stop"}


@dataclass(frozen=True)
class SceneFrame:
    """The map -> scene transform: translate to `centre`, mirror y."""

    centre: np.ndarray  # [2] m, map frame

    def points(self, xy: np.ndarray) -> np.ndarray:
        """Map points [..., 2] -> scene points."""
        xy = np.asarray(xy, dtype=np.float64)
        return np.stack([xy[..., 0] - self.centre[0], self.centre[1] - xy[..., 1]], axis=-1)

    @staticmethod
    def headings(psi: np.ndarray) -> np.ndarray:
        """Map headings [rad] -> scene headings (y mirrored)."""
        return -np.asarray(psi, dtype=np.float64)


def frame_around(xy: np.ndarray) -> SceneFrame:
    """The frame centred on the middle of the box of map points [M, 2]."""
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return SceneFrame(np.round((lo + hi) / 2, 1))


def scene_bounds(points: np.ndarray, margin_m: float) -> Bounds:
    """The box of scene points [M, 2] plus a margin, to whole metres."""
    lo = np.floor(points.min(axis=0) - margin_m)
    hi = np.ceil(points.max(axis=0) + margin_m)
    return Bounds(x_min_m=float(lo[0]), x_max_m=float(hi[0]), y_min_m=float(lo[1]),
                  y_max_m=float(hi[1]))


def driven_area(points: np.ndarray, bounds: Bounds, cell_m: float) -> DrivenArea:
    """Cells of `cell_m` holding a recorded position (scene points [M, 2]), grown by one cell
    so a lane a car drove down reads as a band of road."""
    cols = int(np.ceil((bounds.x_max_m - bounds.x_min_m) / cell_m))
    rows = int(np.ceil((bounds.y_max_m - bounds.y_min_m) / cell_m))
    grid = np.zeros((rows, cols), dtype=bool)
    c = ((points[:, 0] - bounds.x_min_m) // cell_m).astype(int)
    r = ((points[:, 1] - bounds.y_min_m) // cell_m).astype(int)
    inside = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
    grid[r[inside], c[inside]] = True
    grid = ndimage.binary_dilation(grid, structure=np.ones((3, 3), dtype=bool))
    return DrivenArea(cell_m=cell_m, x0_m=bounds.x_min_m, y0_m=bounds.y_min_m,
                      runs=row_runs(grid))


def row_runs(grid: np.ndarray) -> list[list[int]]:
    """[row, first col, last col] of every run of True cells, row by row."""
    runs = []
    for row, cells in enumerate(grid):
        padded = np.concatenate([[False], cells, [False]]).astype(np.int8)
        edges = np.flatnonzero(np.diff(padded))
        runs += [[row, int(a), int(b) - 1] for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return runs


def simplify(points: np.ndarray, tolerance_m: float) -> np.ndarray:
    """Ramer-Douglas-Peucker: drop points within `tolerance_m` of the simplified line."""
    if len(points) < 3:
        return points
    start, end = points[0], points[-1]
    chord = end - start
    length = np.hypot(*chord)
    rel = points[1:-1] - start
    if length < 1e-9:
        dist = np.hypot(rel[:, 0], rel[:, 1])
    else:
        dist = np.abs(chord[0] * rel[:, 1] - chord[1] * rel[:, 0]) / length
    k = int(np.argmax(dist))
    if dist[k] <= tolerance_m:
        return np.stack([start, end])
    left = simplify(points[: k + 2], tolerance_m)
    return np.concatenate([left[:-1], simplify(points[k + 1:], tolerance_m)])


def scene_lines(lines: list[LaneLine], frame: SceneFrame, bounds: Bounds) -> list[Polyline]:
    """The map's lines of a drawn kind that reach into the bounds, in the scene frame."""
    out = []
    lo = np.array([bounds.x_min_m, bounds.y_min_m])
    hi = np.array([bounds.x_max_m, bounds.y_max_m])
    for line in lines:
        kind = LINE_KINDS.get(line.kind)
        points = frame.points(line.points)
        if kind is None or not np.all((points >= lo) & (points <= hi), axis=1).any():
            continue
        points = np.round(simplify(points, SIMPLIFY_M), LINE_DECIMALS)
        out.append(Polyline(kind=kind, dashed=line.subtype == "dashed", points=points.tolist()))
    return out


def recorded_scene(world: str, config: RecordedConfig, source: str, frame: SceneFrame,
                   pair_points: np.ndarray, driven_points: np.ndarray,
                   lines: list[LaneLine]) -> Scene:
    """The scene of a recorded world: bounds around its pairs, the map's lines, the driven
    area of every recorded agent (scene points [M, 2] both)."""
    bounds = scene_bounds(pair_points, config.scene_margin_m)
    look = config.agent.model_dump()
    recorded = RecordedScene(source=source, lines=scene_lines(lines, frame, bounds),
                             driven=driven_area(driven_points, bounds, config.driven_cell_m),
                             view_span_m=config.view_span_m)
    return Scene(world=world, dt_s=config.dt_s,
                 frame=(f"recorded: x, y [m] = the recordings' x - {frame.centre[0]:g}, "
                        f"{frame.centre[1]:g} - y (map y up, drawn down)"),
                 bounds=bounds,
                 agents=[AgentShape(name="robot", color=ROBOT_COLOR, **look),
                         AgentShape(name="human", color=HUMAN_COLOR, **look)],
                 recorded=recorded)
