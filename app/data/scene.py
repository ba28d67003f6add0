"""One JSON-able description of a world's geometry, shared by plots, trial bank and browser.

Plots draw it from its JSON form with app.core.scene_plot.draw_scene.
"""

from pydantic import Field

from app.configio import StrictModel, omitted_when_empty


class Bounds(StrictModel):
    """Axis-aligned drawable area [m]."""

    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float


class Lane(StrictModel):
    """A straight lane parallel to x; lane 0 is the leftmost (smallest y)."""

    index: int
    y_center_m: float
    width_m: float


class Circle(StrictModel):
    """A circular obstacle or goal region."""

    x_m: float
    y_m: float
    radius_m: float
    label: str = ""


class AgentShape(StrictModel):
    """How an agent is drawn: a car (rectangle with heading) or a disc."""

    name: str
    kind: str = Field(pattern="^(car|disc)$")
    length_m: float
    width_m: float
    color: str


class Polyline(StrictModel):
    """A line drawn under the agents (a map's lane border, kerb or stop line), scene frame.
    `virtual` (an unpainted lanelet border) is only in banks built before such lines were
    left out of the scene; the page does not draw it."""

    kind: str = Field(pattern="^(border|kerb|virtual|stop)$")
    dashed: bool = False
    points: list[list[float]] = Field(min_length=2)  # [[x, y], ...] m


class DrivenArea(StrictModel):
    """Where recorded agents went, as square cells: the road a map would draw, from the data.

    Cell (row, col) spans x in x0 + col * cell, y in y0 + row * cell; `runs` lists each
    row's occupied cells as [row, first col, last col] (inclusive).
    """

    cell_m: float = Field(gt=0)
    x0_m: float
    y0_m: float
    runs: list[list[int]]


class RecordedScene(StrictModel):
    """What a recorded world adds to its scene: where the data came from, the map's lines,
    the driven area and how large the clip's view is as it follows the robot."""

    source: str  # e.g. "INTERACTION DR_USA_Roundabout_FT (v1.2)"
    lines: list[Polyline] = []
    driven: DrivenArea | None = None
    view_span_m: float = Field(gt=0)  # the clip shows a square this wide around the robot


class Scene(StrictModel):
    """Everything needed to draw a world; `frame` says what the coordinates mean."""

    world: str
    dt_s: float
    frame: str
    frame_speed_mps: float = 0.0  # speed of the displayed frame along +x (markings scroll)
    bounds: Bounds
    lanes: list[Lane] = []
    obstacles: list[Circle] = []
    goals: list[Circle] = []
    agents: list[AgentShape]
    recorded: RecordedScene | None = None

    # a simulated world's scene serialises exactly as before `recorded` existed, so the
    # shipped bundle's scenes, clip hashes and trajectory files keep their bytes
    _without_unset_recorded = omitted_when_empty("recorded")


# Okabe-Ito colours (distinguishable for colour-blind readers); label colours for plots are
# in app/core/scene_plot.py. Plots and each scene's `agents[].color` use these.
ROBOT_COLOR = "#0072B2"
HUMAN_COLOR = "#E69F00"

# What the browser draws a scene with (frontend/static/js/scene.js; the pages get it from
# app/http/routes/pages.py, which also serves the legend's two as CSS). Every agent, trace,
# marker and goal is at least 3:1 against the ground it is drawn on (WCAG 2.1 SC 1.4.11;
# tests/e2e measures it on the canvas), which a plot on white paper does not have to meet:
# - the person is a darker orange than HUMAN_COLOR, which is 2.2:1 on white; the browser
#   ignores a scene's `agents[].color` and draws the robot and the person with these;
# - the road is light enough for both agents (dark asphalt left the blue robot at 1.2:1);
# - goal rings are distinct from both agents, each >= 5:1 on the field, where plots cycle
#   through app/core/scene_plot.py LABEL_COLORS on white;
# - a recorded scene (`map`) reads as a road map: a pale green field, the driven area a light
#   asphalt grey that reads as a band on it by its hue more than its lightness (1.14:1) and
#   is light enough for both agents (robot 4.0:1, person 3.6:1; under the reach disc's tint
#   the robot's anti-aliased outline still 3.2:1, where #d8dadd left it at 2.9:1); kerbs a
#   dark slate (8.1:1 on the road, drawn thick), painted lane borders a mid grey (3.6:1,
#   thin), stop lines a dark red no agent or model is drawn in (5.7:1, a thick bar); a
#   virtual lanelet border (no paint) is not drawn.
BROWSER_PALETTE = {
    "robot": ROBOT_COLOR,
    "human": "#B35C00",
    "human_text": "#7a4000",  # the person's tag, on a white label
    "ground": {"field": "#fbfbf8", "road": "#e8eaed", "shoulder": "#cfd8c8"},
    "lane_mark": "#5f6368",
    "goals": ["#007A5A", "#6A3D9A", "#A0306A", "#333333"],
    "map": {"field": "#edf2e4", "road": "#e0e2e5", "kerb": "#3c4043", "border": "#70757a",
            "stop": "#9e2a2b"},
}
