"""One JSON-able description of a world's geometry, shared by plots, trial bank and browser.

Plots draw it from its JSON form with analysis.scene_plot.draw_scene.
"""

from pydantic import Field

from app.configio import StrictModel


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


# Okabe-Ito colours (distinguishable for colour-blind readers); label colours for plots are
# in analysis/scene_plot.py.
ROBOT_COLOR = "#0072B2"
HUMAN_COLOR = "#E69F00"
