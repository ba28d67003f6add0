"""Vector fields of a trained model: fix z, decode the robot's next action over a grid.

For Ours each used FSQ code is one field; for the VAE each k-means centre of validation
latents is one (k = number of codes Ours uses), so the two can be compared side by side.
"""

from pathlib import Path

import numpy as np

from app.core.files import atomic_path, write_json
from app.core.scene_plot import draw_scene
from app.data.scene import HUMAN_COLOR, Scene
from app.learning.checkpoint import TrainedModel, load_model


def grid_points(scene: Scene, grid_n: int) -> tuple[np.ndarray, np.ndarray]:
    """grid_n x grid_n robot positions inside the scene bounds (xs, ys, cell centres)."""
    b = scene.bounds
    xs = b.x_min_m + (np.arange(grid_n) + 0.5) * (b.x_max_m - b.x_min_m) / grid_n
    ys = b.y_min_m + (np.arange(grid_n) + 0.5) * (b.y_max_m - b.y_min_m) / grid_n
    return xs, ys


def vector_field(model: TrainedModel, scene: Scene, human_position, grid_n: int) -> dict:
    """JSON-able field per used code: grid xs/ys and the first predicted robot action
    [grid_n*grid_n, 2] m/s at each robot position (row-major over ys, then xs)."""
    xs, ys = grid_points(scene, grid_n)
    gx, gy = np.meshgrid(xs, ys)
    robot = np.stack([gx.ravel(), gy.ravel()], axis=-1)
    human = np.broadcast_to(np.asarray(human_position, dtype=np.float32), robot.shape)
    states = np.stack([robot, human], axis=1).astype(np.float32)
    fields = []
    for entry in model.codes.get("used", []):  # most used first
        z = model.latent_of_code(entry["code"])
        actions = model.predict(z, states)
        fields.append({"code": entry["code"], "z": z.tolist(), "share": entry["share"],
                       "majority": entry["majority"],
                       "actions": actions[:, 0].round(4).tolist(),
                       "actions_all_steps": actions.round(4).tolist()})
    return {"kind": model.name, "world": model.world, "content_hash": model.content_hash,
            "grid_n": grid_n, "xs": xs.tolist(), "ys": ys.tolist(),
            "human_position": [float(v) for v in human_position], "codes": fields}


def primary_label(names) -> str | None:
    """The robot label a title reports: one with a derived variant (intent/goal) first."""
    names = list(names)
    derived = [n for n in names if n.startswith("robot_")
               and (f"{n}_in_progress" in names or f"{n}_before_arrival" in names)]
    robot = [n for n in names if n.startswith("robot_")]
    return (derived or robot or names or [None])[0]


def _title(model: TrainedModel, entry: dict) -> str:
    name = primary_label(entry["majority"])
    what = "no label"
    if name:
        top = entry["majority"][name]
        what = f"{name} = {top['label']} ({top['fraction']:.0%})"
    cluster = "code" if model.name == "ours" else "k-means cluster"
    return f"{model.world} / {model.name}: {cluster} {entry['code']}, {entry['share']:.0%} of " \
           f"validation windows\nmostly {what}"


def _plot_field(model: TrainedModel, scene: Scene, field: dict, entry: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = scene.bounds
    aspect = (b.x_max_m - b.x_min_m) / max(b.y_max_m - b.y_min_m, 1e-6)
    fig, ax = plt.subplots(figsize=(min(12, 3 + 3 * aspect), 4 if aspect > 2 else 6))
    draw_scene(ax, scene.model_dump())
    gx, gy = np.meshgrid(field["xs"], field["ys"])
    actions = np.asarray(entry["actions"]).reshape(len(field["ys"]), len(field["xs"]), 2)
    # colour by the y component so that lateral moves (merges) stand out even where
    # the x component dominates the arrow's length
    limit = max(float(np.abs(actions[..., 1]).max()), 1e-3)
    arrows = ax.quiver(gx, gy, actions[..., 0], actions[..., 1], actions[..., 1], cmap="PuOr_r",
                       clim=(-limit, limit), angles="xy", pivot="mid", zorder=3)
    fig.colorbar(arrows, ax=ax, shrink=0.6, pad=0.01, label="vy [m/s] (y grows downwards)")
    hx, hy = field["human_position"]
    ax.plot([hx], [hy], "o", color=HUMAN_COLOR, markersize=10, markeredgecolor="k",
            zorder=4, label="human (fixed)")
    ax.set_title(_title(model, entry), fontsize=9)
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def write_fields(checkpoint: Path, out_dir: Path | None = None, grid_n: int = 15,
                 human_position=None) -> list[Path]:
    """One quiver PNG per used code over the checkpoint's scene, plus fields.json."""
    model = load_model(checkpoint)
    out_dir = Path(out_dir) if out_dir else Path(checkpoint).parent / "fields"
    scene = Scene.model_validate(model.data_meta["scene"])
    human = human_position if human_position is not None \
        else model.data_meta["human_end_median"]
    field = vector_field(model, scene, human, grid_n)
    paths = []
    for entry in field["codes"]:
        path = out_dir / f"field_code{entry['code']}.png"
        _plot_field(model, scene, field, entry, path)
        paths.append(path)
    write_json(out_dir / "fields.json", field)
    return [*paths, out_dir / "fields.json"]
