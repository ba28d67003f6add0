"""Draw a world's scene, given as its JSON description (bank.json's `scene`), on a matplotlib axis.

Every figure over a scene uses this: the analysis report's field panels, the simulated
trajectories (app/worlds/plots.py) and the models' vector fields (app/learning/fields.py).
"""

# Okabe-Ito colours: distinguishable for colour-blind readers.
LABEL_COLORS = ["#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442", "#000000"]


def draw_scene(ax, scene: dict) -> None:
    """Draw the scene's lanes, obstacles and goals on `ax` (y grows downwards)."""
    from matplotlib.patches import Circle, Rectangle

    b = scene["bounds"]
    ax.set_xlim(b["x_min_m"], b["x_max_m"])
    ax.set_ylim(b["y_max_m"], b["y_min_m"])
    ax.set_aspect("equal")
    for lane in scene.get("lanes", []):
        top = lane["y_center_m"] - lane["width_m"] / 2
        ax.add_patch(Rectangle((b["x_min_m"], top), b["x_max_m"] - b["x_min_m"], lane["width_m"],
                               facecolor="#eeeeee", edgecolor="#999999", lw=0.6, zorder=0))
    for obstacle in scene.get("obstacles", []):
        ax.add_patch(Circle((obstacle["x_m"], obstacle["y_m"]), obstacle["radius_m"],
                            color="#555555", zorder=1))
    for k, goal in enumerate(scene.get("goals", [])):
        ax.add_patch(Circle((goal["x_m"], goal["y_m"]), goal["radius_m"], fill=False, lw=1.5,
                            edgecolor=LABEL_COLORS[k % len(LABEL_COLORS)], zorder=1))
        ax.annotate(goal.get("label") or f"goal {k}", (goal["x_m"], goal["y_m"]), ha="center",
                    va="center", fontsize=7, zorder=2)
    draw_recorded(ax, scene.get("recorded"))


# how a recorded scene's map lines are drawn: colour, width, dashes (app/data/scene.py Polyline)
LINE_STYLES = {"kerb": ("#555555", 1.2, "-"), "border": ("#888888", 0.8, "-"),
               "virtual": ("#bbbbbb", 0.6, ":"), "stop": ("#aa4444", 1.0, "-")}


def draw_recorded(ax, recorded: dict | None) -> None:
    """A recorded world's driven area (as road) and map lines, under everything else."""
    if not recorded:
        return
    from matplotlib.patches import Rectangle

    driven = recorded.get("driven")
    if driven:
        cell = driven["cell_m"]
        for row, first, last in driven["runs"]:
            ax.add_patch(Rectangle((driven["x0_m"] + first * cell, driven["y0_m"] + row * cell),
                                   (last - first + 1) * cell, cell, facecolor="#e4e4e4",
                                   edgecolor="none", zorder=0))
    for line in recorded.get("lines", []):
        color, width, style = LINE_STYLES[line["kind"]]
        xs, ys = zip(*line["points"], strict=True)
        ax.plot(xs, ys, color=color, lw=width, ls="--" if line["dashed"] else style, zorder=0.5)
