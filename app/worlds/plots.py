"""Pictures of simulated trajectories over their scene."""

from pathlib import Path

import numpy as np

from app.core.scene_plot import LABEL_COLORS, draw_scene
from app.data.scene import HUMAN_COLOR
from app.data.trajectory import HUMAN, ROBOT, TrajectorySet
from app.layout import Layout


def plot_simulated(layout: Layout, world: str, config_path: Path | None = None,
                   policy: str = "mpc") -> Path:
    """data/<world>/trajectories.png: the world's simulated trajectories, robot coloured by
    the world's robot label."""
    from app.worlds.registry import build_world

    label = build_world(world, config_path, policy).robot_label
    return plot_trajectories(TrajectorySet.load(layout.trajectories(world)),
                             layout.trajectories_plot(world), label)


def plot_trajectories(trajs: TrajectorySet, path: Path, label: str, count: int = 20) -> Path:
    """PNG of the first `count` trajectories: robot coloured by `label`, human in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scene = trajs.scene
    width = 12 if scene.lanes else 7
    fig, ax = plt.subplots(figsize=(width, 7 if not scene.lanes else 3.2))
    draw_scene(ax, scene.model_dump())
    names = trajs.label_names[label]
    for i in range(min(count, len(trajs))):
        end = int(trajs.lengths[i]) + 1
        cls = int(trajs.labels[label][i])
        robot = trajs.positions[i, :end, ROBOT]
        human = trajs.positions[i, :end, HUMAN]
        ax.plot(human[:, 0], human[:, 1], color=HUMAN_COLOR, lw=0.8, alpha=0.6, ls="--")
        ax.plot(robot[:, 0], robot[:, 1], color=LABEL_COLORS[cls % len(LABEL_COLORS)],
                lw=1.4, alpha=0.9, marker=".", ms=3)
        ax.plot(*robot[0], "o", color=LABEL_COLORS[cls % len(LABEL_COLORS)], ms=4)
    handles = [plt.Line2D([], [], color=LABEL_COLORS[k % len(LABEL_COLORS)], label=f"robot: {n}")
               for k, n in enumerate(names)]
    handles.append(plt.Line2D([], [], color=HUMAN_COLOR, ls="--", label="human"))
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8)
    ax.set_title(f"{trajs.world}: {min(count, len(trajs))} trajectories "
                 f"(dt = {trajs.dt_s} s, mean length {np.mean(trajs.lengths):.1f} steps)")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
