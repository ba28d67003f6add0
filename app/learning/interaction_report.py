"""Figures and the HTML report of the INTERACTION experiment (interaction_experiment.py)."""

import base64
import csv
import html
import json
from pathlib import Path

import numpy as np

from analysis.scene_plot import LABEL_COLORS
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR
from app.data.trajectory import HUMAN, ROBOT
from app.data.windows import Windows
from app.fileio import atomic_path, write_json
from app.learning.interaction_experiment import MODELS, Experiment, InteractionConfig

MODEL_NAMES = {"ours": "Ours", "vae": "VAE", "cv": "constant velocity"}


# ---------------------------------------------------------------- figures


def _axes_over_scene(ax, exp: Experiment) -> None:
    from app.data.lanelet_map import draw_lane_lines

    b = exp.train.trajs.scene.bounds
    draw_lane_lines(ax, exp.lane_lines)
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


def plot_errors(summary: dict, path: Path) -> Path:
    """Mean next-action alignment error per model with the 10 per-seed means as dots."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.6))
    colors = {"ours": "#0072B2", "vae": "#D55E00", "cv": "#999999"}
    for k, m in enumerate(MODELS):
        values = np.asarray(summary["per_seed_alignment_error"][m])
        ax.bar(k, values.mean(), color=colors[m], alpha=0.75)
        if m != "cv":
            ax.errorbar(k, values.mean(), yerr=values.std(ddof=1), color="k", capsize=4)
            jitter = np.linspace(-0.2, 0.2, len(values))
            ax.plot(k + jitter, values, "o", color="k", ms=3)
    ax.set_xticks(range(len(MODELS)), [MODEL_NAMES[m] for m in MODELS])
    p = summary["tests"]["ours_vs_vae"]["p_two_sided"]
    ax.set_ylabel("alignment error 1 - cos (next action)")
    ax.set_title(f"{summary['scenario']}: {summary['seeds']} seeds; Ours vs VAE p = {p:.2g}",
                 fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_pairs(exp: Experiment, path: Path, count: int = 80) -> Path:
    """Some train pairs over the map: robot coloured by its label, human dashed."""
    import matplotlib.pyplot as plt

    trajs = exp.train.trajs
    name = "robot_manoeuvre" if "robot_manoeuvre" in trajs.labels else "robot_turn"
    names = trajs.label_names[name]
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    _axes_over_scene(ax, exp)
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
    ax.set_title(f"{exp.scenario}: {len(pick)} of {len(trajs)} train pairs "
                 f"(robot by {name})", fontsize=9)
    return _save(fig, path)


def field_grid(exp: Experiment, cfg: InteractionConfig) -> np.ndarray:
    """Grid points [G, 2] over the scenario area, kept where robots were seen (within 4 m)."""
    b = exp.train.trajs.scene.bounds
    xs = np.linspace(b.x_min_m, b.x_max_m, cfg.field_grid)
    ys = np.linspace(b.y_min_m, b.y_max_m, cfg.field_grid)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    seen = exp.train.trajs.positions[:, :, ROBOT].reshape(-1, 2)
    cell = 4.0
    occupied = {tuple(k) for k in np.floor(seen / cell).astype(np.int64)}
    keys = np.floor(grid / cell).astype(np.int64)
    near = [any((k[0] + dx, k[1] + dy) in occupied for dx in (-1, 0, 1) for dy in (-1, 0, 1))
            for k in keys]
    return grid[np.array(near, dtype=bool)]


def plot_fields(exp: Experiment, cfg: InteractionConfig, model, codes: np.ndarray,
                windows: Windows, scored: np.ndarray, path: Path) -> Path:
    """Per most-used code: the decoded next robot action over the area (human fixed)."""
    import matplotlib.pyplot as plt

    values, counts = np.unique(codes[scored], return_counts=True)
    top = values[np.argsort(-counts)][: cfg.field_codes]
    grid = field_grid(exp, cfg)
    cols = min(3, len(top))
    rows = int(np.ceil(len(top) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    for ax, code in zip(axes.flat, top, strict=False):
        in_code = scored & (codes == code)
        human = np.median(windows.end_states[in_code, HUMAN], axis=0)
        states = np.stack([grid, np.repeat(human[None], len(grid), axis=0)], axis=1)
        action = model.predict(model.latent_of_code(int(code)), states)[:, 0]
        speed = np.maximum(np.linalg.norm(action, axis=1, keepdims=True), 1e-6)
        _axes_over_scene(ax, exp)
        ends = windows.end_states[in_code, ROBOT]
        ax.plot(ends[:, 0], ends[:, 1], ".", color=ROBOT_COLOR, ms=2, alpha=0.35)
        ax.quiver(grid[:, 0], grid[:, 1], *(action / speed).T, angles="xy", color="#333333",
                  width=0.004, scale=cfg.field_grid * 1.3)
        ax.plot(*human, "s", color=HUMAN_COLOR, ms=7, mec="k")
        ax.set_title(f"{MODEL_NAMES[model.kind]} code {int(code)}: "
                     f"{in_code.sum() / scored.sum():.0%} of val windows", fontsize=8)
    for ax in list(axes.flat)[len(top):]:
        ax.axis("off")
    fig.suptitle(f"{exp.scenario}: next-action field per code (arrows = direction; blue dots "
                 "= robot positions of val windows with this code; square = human)", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def write_figures(exp: Experiment, cfg: InteractionConfig, per_seed: list[dict], summary: dict,
                  windows: Windows, scored: np.ndarray, out_dir: Path) -> list:
    """errors.png, pairs.png and one vector-field figure per model (seed 0's models)."""
    import matplotlib

    matplotlib.use("Agg")
    from app.learning.checkpoint import load_model

    figures = [plot_errors(summary, out_dir / "errors.png"),
               plot_pairs(exp, out_dir / "pairs.png")]
    for kind in ("ours", "vae"):
        model = load_model(Path(per_seed[0][kind]["checkpoint"]))
        codes = model.codes_of(model.encode_batch(windows.segment_positions))
        figures.append(plot_fields(exp, cfg, model, codes, windows, scored,
                                   out_dir / f"fields_{kind}.png"))
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


def _f(value: float, digits: int = 3) -> str:
    return "-" if value is None or value != value else f"{value:.{digits}f}"


def verdict(summary: dict) -> str:
    """One honest sentence: who wins on next-action alignment error and by how much."""
    means = summary["mean_alignment_error"]
    w, r = summary["winner"], summary["runner_up"]
    test = summary["tests"].get(f"{w}_vs_{r}") or summary["tests"].get(f"{r}_vs_{w}")
    return (f"{MODEL_NAMES[w]} has the lowest mean next-action alignment error "
            f"({means[w]:.4f}), {summary['winner_margin']:.4f} below {MODEL_NAMES[r]} "
            f"({means[r]:.4f}; paired t-test over seeds p = {test['p_two_sided']:.2g}).")


def render_html(summary: dict, figures: list[Path]) -> str:
    """The report page."""
    rows = "".join(
        f"<tr><td>{MODEL_NAMES[m]}</td>"
        + "".join(f"<td>{_f(summary['models'][m][k]['mean'])} &plusmn; "
                  f"{_f(summary['models'][m][k]['sd'])}</td>"
                  for k in ("alignment_error", "ade_m", "fde_m")) + "</tr>" for m in MODELS)
    tests = "".join(
        f"<tr><td>{name.replace('_vs_', ' vs ').replace('cv', 'CV')}</td>"
        f"<td>{_f(t['mean_diff'])} [{_f(t['ci95_low'])}, {_f(t['ci95_high'])}]</td>"
        f"<td>{_f(t['t'], 2)}</td><td>{t['p_two_sided']:.3g}</td><td>{_f(t['d_z'], 2)}</td>"
        "</tr>" for name, t in summary["tests"].items())
    latent = "".join(
        f"<tr><td>{MODEL_NAMES[m]}</td><td>{html.escape(k)}</td>"
        f"<td>{_f(v['mean'])} &plusmn; {_f(v['sd'])}</td></tr>"
        for m in ("ours", "vae") for k, v in summary["models"][m].items()
        if k.startswith(("purity", "nmi", "codes_used", "perplexity")))
    images = "".join(
        f"<figure><img alt='{html.escape(p.stem)}' src='data:image/png;base64,"
        f"{base64.b64encode(p.read_bytes()).decode()}'><figcaption>{html.escape(p.name)}"
        "</figcaption></figure>" for p in figures)
    s = summary
    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>INTERACTION {html.escape(s['scenario'])}</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;
font-size:13px;text-align:right}}img{{max-width:100%}}</style></head><body>
<h1>INTERACTION {html.escape(s['scenario'])} ({html.escape(s['layout'])} layout)</h1>
<p><b>{html.escape(verdict(s))}</b></p>
<p>{s['pairs']['train']} train and {s['pairs']['val']} val robot/human pairs; the models see
{s['segment_steps']} steps of {s['dt_s']:.1f} s ({s['observed_s']:.1f} s, 10 Hz downsampled)
and predict {s['predict_steps']} robot actions. {s['val_windows_scored']} of
{s['val_windows']} val windows are scored (true next speed at least the threshold).
Alignment error = 1 - cos between predicted and true next action (0 same direction,
2 opposite). Mean &plusmn; SD over {s['seeds']} seeds (training runs); constant velocity is
deterministic.</p>
<h2>Errors</h2><table><tr><th>model</th><th>alignment error</th><th>ADE [m]</th>
<th>FDE [m]</th></tr>{rows}</table>
<h2>Paired t-tests over seeds (difference = first - second)</h2>
<p>Constant velocity gives the same value for every seed, so its comparisons are in effect
one-sample t-tests of the seed means against that value.</p>
<table><tr><th>comparison</th><th>mean diff [95% CI]</th><th>t</th><th>p</th><th>d_z</th></tr>
{tests}</table>
<h2>Latent codes vs labels (val windows)</h2><table><tr><th>model</th><th>measure</th>
<th>mean &plusmn; SD</th></tr>{latent}</table>
<p>Purity if every window got the most common label (chance level):
{html.escape(", ".join(f"{k} {v:.3f}" for k, v in s["purity_chance"].items()))}.</p>
<p>Label counts: {html.escape(json.dumps(s['label_counts']))}</p>
<h2>Figures</h2>{images}
<p>All numbers: summary.json and per_seed.csv beside this file.</p></body></html>
"""
