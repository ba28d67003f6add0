"""One JSON-able description of a world's geometry, shared by plots, trial bank and browser."""

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


# Okabe-Ito colours: distinguishable for colour-blind readers.
ROBOT_COLOR = "#0072B2"
HUMAN_COLOR = "#E69F00"
LABEL_COLORS = ["#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442", "#000000"]


def draw_scene(ax, scene: Scene) -> None:
    """Draw lanes or obstacles and goals of `scene` on a matplotlib axis (y grows downwards)."""
    from matplotlib.patches import Circle as MplCircle
    from matplotlib.patches import Rectangle

    b = scene.bounds
    ax.set_xlim(b.x_min_m, b.x_max_m)
    ax.set_ylim(b.y_max_m, b.y_min_m)
    ax.set_aspect("equal")
    for lane in scene.lanes:
        top = lane.y_center_m - lane.width_m / 2
        ax.add_patch(Rectangle((b.x_min_m, top), b.x_max_m - b.x_min_m, lane.width_m,
                               facecolor="#eeeeee", edgecolor="#999999", lw=0.6, zorder=0))
    for obs in scene.obstacles:
        ax.add_patch(MplCircle((obs.x_m, obs.y_m), obs.radius_m, color="#555555", zorder=1))
    for k, goal in enumerate(scene.goals):
        ax.add_patch(MplCircle((goal.x_m, goal.y_m), goal.radius_m, fill=False, lw=1.5,
                               edgecolor=LABEL_COLORS[k % len(LABEL_COLORS)], zorder=1))
        ax.annotate(goal.label or f"goal {k}", (goal.x_m, goal.y_m), ha="center",
                    va="center", fontsize=7, zorder=2)
