"""Figures and the HTML report of the INTERACTION experiment.

experiment.py runs the experiment and hands this module plain results (the
summary, per-seed rows) and `FigureInputs`; nothing here imports the experiment back. The
page is analysis/templates/interaction_report.html.j2.
"""

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.html import render_page
from app.core.files import atomic_path, write_json
from app.core.scene_plot import LABEL_COLORS
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR
from app.data.trajectory import HUMAN, ROBOT, TrajectorySet
from app.data.windows import Windows
from app.recordings.lanelet_map import LaneLine

MODEL_NAMES = {"ours": "Ours", "vae": "VAE", "cv": "constant velocity"}


@dataclass(frozen=True)
class FigureInputs:
    """What the figures draw: the train pairs over the map, the scored val windows and the
    vector-field settings (grid points per side, most used codes per model)."""

    scenario: str
    train: TrajectorySet
    lane_lines: list[LaneLine]
    windows: Windows
    scored: np.ndarray
    field_grid: int
    field_codes: int


def models_of(summary: dict) -> list[str]:
    """The compared models, in the summary's order (Ours, VAE, constant velocity)."""
    return list(summary["paper_protocol"]["mean_alignment_error"])


# ---------------------------------------------------------------- figures


def _axes_over_scene(ax, inputs: FigureInputs) -> None:
    from app.recordings.lanelet_map import draw_lane_lines

    b = inputs.train.scene.bounds
    draw_lane_lines(ax, inputs.lane_lines)
    ax.set_xlim(b.x_min_m, b.x_max_m)
    ax.set_ylim(b.y_min_m, b.y_max_m)  # map frame: y grows upwards
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


MODEL_COLORS = {"ours": "#0072B2", "vae": "#D55E00", "cv": "#999999"}


def error_panels(summary: dict) -> list[tuple[str, dict[str, list[float]]]]:
    """(title, model -> per-seed alignment errors): the next action, then every horizon's
    'all' stratum."""
    primary = summary["paper_protocol"]
    panels = [(f"next action ({summary['dt_s']:g} s, primary)",
               primary["per_seed_alignment_error"])]
    for h, strata in summary.get("by_horizon", {}).items():
        panels.append((f"{h} s displacement", {m: cell["alignment_error"]["per_seed"]
                                                 for m, cell in strata["all"].items()}))
    return panels


def _bars_with_seeds(ax, per_seed: dict[str, list[float]], models: list[str]) -> None:
    for k, m in enumerate(models):
        values = np.asarray(per_seed[m])
        ax.bar(k, values.mean(), color=MODEL_COLORS[m], alpha=0.75)
        if m != "cv":
            ax.errorbar(k, values.mean(), yerr=values.std(ddof=1), color="k", capsize=4)
            jitter = np.linspace(-0.2, 0.2, len(values))
            ax.plot(k + jitter, values, "o", color="k", ms=3)
    ax.set_xticks(range(len(models)), [MODEL_NAMES[m] for m in models], fontsize=7)


def plot_errors(summary: dict, path: Path) -> Path:
    """Mean alignment error per model and horizon with the per-seed means as dots."""
    import matplotlib.pyplot as plt

    panels = error_panels(summary)
    models = models_of(summary)
    fig, axes = plt.subplots(1, len(panels), figsize=(3.6 * len(panels), 3.6), squeeze=False)
    for ax, (title, per_seed) in zip(axes[0], panels, strict=True):
        _bars_with_seeds(ax, per_seed, models)
        ax.set_title(title, fontsize=8)
    axes[0, 0].set_ylabel("alignment error 1 - cos")
    p = summary["paper_protocol"]["tests"]["ours_vs_vae"]["p_two_sided"]
    fig.suptitle(f"{summary['scenario']}: {summary['seeds']} seeds (dots), all val windows; "
                 f"next action Ours vs VAE p = {p:.2g}", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_pairs(inputs: FigureInputs, path: Path, count: int = 80) -> Path:
    """Some train pairs over the map: robot coloured by its label, human dashed."""
    import matplotlib.pyplot as plt

    trajs = inputs.train
    name = "turn" if "turn" in trajs.labels else "robot_turn"
    names = trajs.label_names[name]
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    _axes_over_scene(ax, inputs)
    pick = np.linspace(0, len(trajs) - 1, min(count, len(trajs))).round().astype(int)
    for i in pick:
        cls = int(trajs.labels[name][i])
        ax.plot(*trajs.positions[i, :, HUMAN].T, color=HUMAN_COLOR, lw=0.6, ls="--", alpha=0.5)
        ax.plot(*trajs.positions[i, :, ROBOT].T, lw=1.2,
                color=LABEL_COLORS[cls % len(LABEL_COLORS)] if cls >= 0 else "k")
    handles = [plt.Line2D([], [], color=LABEL_COLORS[k % len(LABEL_COLORS)], label=n)
               for k, n in enumerate(names)]
    handles.append(plt.Line2D([], [], color=HUMAN_COLOR, ls="--", label="human"))
    ax.legend(handles=handles, fontsize=7, loc="upper right")
    ax.set_title(f"{inputs.scenario}: {len(pick)} of {len(trajs)} train pairs "
                 f"(robot by {name})", fontsize=9)
    return _save(fig, path)


def field_grid(inputs: FigureInputs) -> np.ndarray:
    """Grid points [G, 2] over the scenario area, kept where robots were seen (within 4 m)."""
    b = inputs.train.scene.bounds
    xs = np.linspace(b.x_min_m, b.x_max_m, inputs.field_grid)
    ys = np.linspace(b.y_min_m, b.y_max_m, inputs.field_grid)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    seen = inputs.train.positions[:, :, ROBOT].reshape(-1, 2)
    cell = 4.0
    occupied = {tuple(k) for k in np.floor(seen / cell).astype(np.int64)}
    keys = np.floor(grid / cell).astype(np.int64)
    near = [any((k[0] + dx, k[1] + dy) in occupied for dx in (-1, 0, 1) for dy in (-1, 0, 1))
            for k in keys]
    return grid[np.array(near, dtype=bool)]


def plot_fields(inputs: FigureInputs, model, codes: np.ndarray, path: Path) -> Path:
    """Per most-used code: the decoded next robot action over the area (human fixed)."""
    import matplotlib.pyplot as plt

    windows, scored = inputs.windows, inputs.scored
    values, counts = np.unique(codes[scored], return_counts=True)
    top = values[np.argsort(-counts)][: inputs.field_codes]
    grid = field_grid(inputs)
    cols = min(3, len(top))
    rows = int(np.ceil(len(top) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    for ax, code in zip(axes.flat, top, strict=False):
        in_code = scored & (codes == code)
        human = np.median(windows.end_states[in_code, HUMAN], axis=0)
        states = np.stack([grid, np.repeat(human[None], len(grid), axis=0)], axis=1)
        action = model.predict(model.latent_of_code(int(code)), states)[:, 0]
        speed = np.maximum(np.linalg.norm(action, axis=1, keepdims=True), 1e-6)
        _axes_over_scene(ax, inputs)
        ends = windows.end_states[in_code, ROBOT]
        ax.plot(ends[:, 0], ends[:, 1], ".", color=ROBOT_COLOR, ms=2, alpha=0.35)
        ax.quiver(grid[:, 0], grid[:, 1], *(action / speed).T, angles="xy", color="#333333",
                  width=0.004, scale=inputs.field_grid * 1.3)
        ax.plot(*human, "s", color=HUMAN_COLOR, ms=7, mec="k")
        ax.set_title(f"{MODEL_NAMES[model.name]} code {int(code)}: "
                     f"{in_code.sum() / scored.sum():.0%} of val windows", fontsize=8)
    for ax in list(axes.flat)[len(top):]:
        ax.axis("off")
    fig.suptitle(f"{inputs.scenario}: next-action field per code (arrows = direction; blue dots "
                 "= robot positions of val windows with this code; square = human)", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def write_figures(inputs: FigureInputs, per_seed: list[dict], summary: dict,
                  out_dir: Path) -> list:
    """errors.png, pairs.png and one vector-field figure per model (seed 0's models)."""
    import matplotlib

    matplotlib.use("Agg")
    from app.learning.checkpoint import load_model

    figures = [plot_errors(summary, out_dir / "errors.png"),
               plot_pairs(inputs, out_dir / "pairs.png")]
    for kind in ("ours", "vae"):
        model = load_model(Path(per_seed[0][kind]["checkpoint"]))
        codes = model.codes_of(model.encode_batch(inputs.windows.segment_positions))
        figures.append(plot_fields(inputs, model, codes, out_dir / f"fields_{kind}.png"))
    return figures


# ---------------------------------------------------------------- report


def write_report(out_dir: Path, summary: dict, per_seed: list[dict], figures: list[Path]) -> None:
    """summary.json, per_seed.csv and report.html (figures embedded)."""
    write_json(out_dir / "summary.json", summary)
    with atomic_path(out_dir / "per_seed.csv") as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(["seed", "model", "alignment_error", "ade_m", "fde_m", "codes_used"])
        for r in per_seed:
            for m in ("ours", "vae"):
                writer.writerow([r["seed"], m, f"{r[m]['alignment_error']:.6f}",
                                 f"{r[m]['ade_m']:.6f}", f"{r[m]['fde_m']:.6f}",
                                 r[m]["usage"]["n_codes_used"]])
    with atomic_path(out_dir / "report.html") as tmp:
        tmp.write_text(render_html(summary, figures))


def fixed(value: float | None, digits: int = 3) -> str:
    """A number with fixed digits; None or NaN as '-'."""
    return "-" if value is None or value != value else f"{value:.{digits}f}"


def verdict(summary: dict) -> str:
    """One honest sentence: who wins on next-action alignment error and by how much."""
    primary = summary["paper_protocol"]
    means = primary["mean_alignment_error"]
    w, r = primary["winner"], primary["runner_up"]
    test = primary["tests"].get(f"{w}_vs_{r}") or primary["tests"].get(f"{r}_vs_{w}")
    return (f"{MODEL_NAMES[w]} has the lowest mean next-action alignment error "
            f"({means[w]:.4f}), {primary['winner_margin']:.4f} below {MODEL_NAMES[r]} "
            f"({means[r]:.4f}; paired t-test over seeds p = {test['p_two_sided']:.2g}).")


def frame_verdict(summary: dict) -> str | None:
    """The sensitivity row in one sentence (None when it was not run)."""
    row = summary.get("sensitivity", {}).get("human_relative_frame")
    if row is None:
        return None
    means = row["mean_alignment_error"]
    p = row["tests"]["ours_vs_vae"]["p_two_sided"]
    return (f"Human-relative frame ({row['seeds']} seeds): Ours {means['ours']:.4f}, VAE "
            f"{means['vae']:.4f}, constant velocity {means['cv']:.4f}; lowest "
            f"{MODEL_NAMES[row['winner']]} (Ours vs VAE p = {p:.2g}).")


def render_html(summary: dict, figures: list[Path]) -> str:
    """The report page."""
    return render_page("interaction_report.html.j2", filters={"fixed": fixed, "json": json.dumps},
                       s=summary, p=summary["paper_protocol"], verdict=verdict(summary),
                       r=summary.get("sensitivity", {}).get("human_relative_frame"),
                       models=models_of(summary),
                       names=MODEL_NAMES, figures=figures, page_width_px=1100)
