"""The report's figures (matplotlib Agg; each written as PNG and SVG)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from analysis.fields import (  # noqa: E402
    FIELD_MODELS,
    arrow_length,
    code_panels,
    is_long_and_thin,
    panel_error,
    state_table,
    unit,
)
from analysis.stats import PairedResult, mean_ci95  # noqa: E402
from app.core.contracts import MODEL_COLORS, MODEL_LABELS, model_color, model_label  # noqa: E402
from app.core.scene_plot import draw_scene  # noqa: E402


def save(fig, base: Path) -> list[Path]:
    """Write `base`.png and `base`.svg and close the figure."""
    base = Path(base)
    base.parent.mkdir(parents=True, exist_ok=True)
    paths = [base.with_suffix(".png"), base.with_suffix(".svg")]
    fig.savefig(paths[0], dpi=130)
    fig.savefig(paths[1])
    plt.close(fig)
    return paths


def plot_errors(means: pd.DataFrame, results: dict[str, PairedResult], base: Path,
                models: tuple[str, ...] = ("ours", "vae", "cv")) -> list[Path]:
    """Per world: mean alignment error per model with 95% CI, participants as dots, paired lines."""
    worlds = sorted(means["world"].unique())
    fig, axes = plt.subplots(1, len(worlds), figsize=(4.2 * len(worlds), 4.2), squeeze=False,
                             sharey=True)
    rng = np.random.default_rng(0)
    for ax, world in zip(axes[0], worlds, strict=True):
        group = means[means["world"] == world]
        jitter = rng.uniform(-0.08, 0.08, size=len(group))
        values = np.stack([group[f"err_{m}"].to_numpy() for m in models])
        xs = np.arange(len(models))[None, :] + jitter[:, None]
        lines = np.stack([xs, values.T], axis=-1)  # one polyline per participant
        ax.add_collection(LineCollection(lines, colors="#bbbbbb", linewidths=0.7, zorder=1))
        for i, model in enumerate(models):
            ax.scatter(i + jitter, values[i], s=12, color=model_color(model), alpha=0.6,
                       zorder=2, edgecolor="none")
            mean, low, high = mean_ci95(values[i])
            ax.errorbar(i + 0.28, mean, yerr=[[mean - low], [high - mean]], fmt="o",
                        color="black", ms=6, capsize=4, zorder=3)
        res = results.get(world)
        title = world
        if res is not None:
            title += (f"\nOurs-VAE: t={res.t:.2f}, p={res.p_two_sided:.2g}, "
                      f"d_z={res.d_z:.2f}, n={res.n}")
        ax.set_title(title, fontsize=9)
        ax.set_xticks(range(len(models)), [model_label(m) for m in models])
        ax.set_xlim(-0.5, len(models) - 0.3)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("alignment error (1 - cos), mean per participant")
    fig.suptitle("Alignment with participants' predictions (dots: participants; "
                 "black: mean, 95% CI)", fontsize=9)
    fig.tight_layout()
    return save(fig, base)


def field_panel(ax, states: pd.DataFrame, model: str, scene: dict | None,
                arrow_m: float) -> float:
    """Participants' mean first move and the model's at each start state (unit arrows)."""
    if scene is not None:
        draw_scene(ax, scene)
    else:
        ax.invert_yaxis()
        ax.set_aspect("equal")
    for who, style, width in (("participant", "human", 0.006), (model, model, 0.004)):
        ux, uy = unit(states[f"{who}_vx"].to_numpy(), states[f"{who}_vy"].to_numpy())
        ax.quiver(states["x"], states["y"], ux * arrow_m, uy * arrow_m, angles="xy",
                  scale_units="xy", scale=1, color=MODEL_COLORS[style], width=width, zorder=4,
                  label=MODEL_LABELS[style])
    return panel_error(states, model)


def plot_fields(frame: pd.DataFrame, scenes: dict, base: Path, k: int = 3) -> list[Path]:
    """Per world, for each model's k most common codes: participants' field beside the model's.

    `scenes` maps a world to its scene JSON (bank.json's `scene`); a world without one is
    drawn on bare axes."""
    worlds = sorted(frame["world"].unique())
    models = FIELD_MODELS
    paths: list[Path] = []
    for world in worlds:
        states_w = state_table(frame[frame["world"] == world])
        scene = scenes.get(world)
        wide = scene is not None and is_long_and_thin(scene)
        # panels of a long, thin scene (a road): models side by side, one code per row
        shape = (k, len(models)) if wide else (len(models), k)
        fig, axes = plt.subplots(*shape, squeeze=False,
                                 figsize=(13, 1.9 * k) if wide else (3.4 * k, 3.6 * len(models)))
        arrow_m = arrow_length(scene)
        for r, model in enumerate(models):
            panels = code_panels(states_w, model, k)
            for c in range(k):
                ax = axes[c][r] if wide else axes[r][c]
                if c >= len(panels):
                    ax.axis("off")
                    continue
                code, states = panels[c]
                err = field_panel(ax, states, model, scene, arrow_m)
                if wide:
                    _crop_x(ax, states_w, arrow_m)
                ax.set_title(f"{MODEL_LABELS[model]} code {code}: "
                             f"{states['trial_id'].nunique()} trials, error {err:.2f}", fontsize=8)
                ax.tick_params(labelsize=6)
        _figure_legend(fig)
        fig.suptitle(f"{world}: participants' first moves (black, mean per start state) vs "
                     "each model's, for its most common latent codes", fontsize=9)
        fig.subplots_adjust(left=0.05, right=0.98, bottom=0.1, top=0.9, wspace=0.15, hspace=0.35)
        paths += save(fig, Path(base).with_name(f"{Path(base).name}_{world}"))
    return paths


def _figure_legend(fig) -> None:
    """One legend for the whole figure (participants, Ours, VAE), under the panels."""
    entries: dict = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    fig.legend(list(entries.values()), list(entries), loc="lower center", ncols=len(entries),
               fontsize=8, frameon=False)


def _crop_x(ax, states: pd.DataFrame, margin_m: float) -> None:
    """Show only the stretch of road where the world's start states lie."""
    low, high = states["x"].min() - 2 * margin_m, states["x"].max() + 2 * margin_m
    left, right = ax.get_xlim()
    ax.set_xlim(max(left, low), min(right, high))


def plot_power(curve: pd.DataFrame, alpha: float, preset: str, base: Path) -> list[Path]:
    """Power to detect Ours < VAE vs number of participants, one line per world."""
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    colors = ["#0072B2", "#D55E00", "#009E73"]
    for i, (world, group) in enumerate(curve.groupby("world", sort=True)):
        ax.plot(group["n"], group["power"], color=colors[i % 3], lw=1.8,
                label=f"{world} (d_z = {group['d_z'].iloc[0]:.2f}), participants random")
        if "power_trials_random" in group and group["power_trials_random"].notna().any():
            ax.plot(group["n"], group["power_trials_random"], color=colors[i % 3], lw=1.8,
                    ls="--", label=f"{world}, participants and trials random (primary)")
    ax.axhline(0.8, color="grey", ls="--", lw=0.8)
    ax.axvline(22, color="grey", ls=":", lw=0.8)
    ax.text(22.5, 0.05, "paper: n = 22", fontsize=7, color="grey")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("participants n")
    ax.set_ylabel(f"power (alpha = {alpha})")
    ax.set_title(f"Power to find Ours < VAE with '{preset}' simulated participants", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, base)


def plot_grid_pass_rates(summary: pd.DataFrame, target: float, base: Path) -> list[Path]:
    """Per world, the instrument check's pass rate at each click-noise level, one line per seed
    pair (absolute lane reading): where the study can tell the observers apart, and how far
    that depends on the training run and on how precisely people click."""
    rows = summary[summary["reading"] == "absolute"]
    levels = list(dict.fromkeys(rows["noise"]))  # in the order they were run
    worlds = sorted(rows["world"].unique())
    fig, axes = plt.subplots(1, len(worlds), figsize=(4.8 * len(worlds), 3.6), squeeze=False)
    for ax, world in zip(axes[0], worlds, strict=True):
        for pair, group in rows[rows["world"] == world].groupby("pair"):
            rates = group.set_index("noise")["pass_rate"].reindex(levels)
            ax.plot(range(len(levels)), rates.to_numpy(), marker="o", lw=1.2,
                    label=f"seed pair {pair}")
        ax.axhline(target, color="grey", lw=0.8, ls="--")
        ax.set_xticks(range(len(levels)), levels, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(-0.03, 1.03)
        ax.set_xlabel("click direction noise")
        ax.set_ylabel("pass rate (share of reruns)")
        ax.set_title(f"{world}: coarse vs precise told apart", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, base)


def plot_trial_contrast(by_trial: pd.DataFrame, base: Path) -> list[Path]:
    """Per world, each main trial's err_ours - err_vae for the precise (x) and the coarse (y)
    population: below the diagonal the coarse observers favour Ours more, as the check asks."""
    worlds = sorted(by_trial["world"].unique())
    fig, axes = plt.subplots(1, len(worlds), figsize=(4.6 * len(worlds), 4.2), squeeze=False)
    for ax, world in zip(axes[0], worlds, strict=True):
        rows = by_trial[by_trial["world"] == world]
        x, y = rows["precise_diff"].to_numpy(), rows["coarse_diff"].to_numpy()
        limit = 1.05 * max(np.nanmax(np.abs(np.r_[x, y])), 1e-3)
        ax.plot([-limit, limit], [-limit, limit], color="grey", lw=0.8, ls="--")
        ax.axhline(0, color="grey", lw=0.5)
        ax.axvline(0, color="grey", lw=0.5)
        below = y < x
        ax.scatter(x[below], y[below], s=18, color="#0072B2",
                   label=f"coarse favours Ours more ({below.sum()})")
        ax.scatter(x[~below], y[~below], s=18, color="#D55E00",
                   label=f"precise favours Ours more ({(~below).sum()})")
        ax.set_xlim(-limit, limit)
        ax.set_ylim(-limit, limit)
        ax.set_aspect("equal")
        ax.set_xlabel("precise observers: err_ours - err_vae")
        ax.set_ylabel("coarse observers: err_ours - err_vae")
        ax.set_title(f"{world}: one point per main trial", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, base)


VERDICT_COLORS = {"ours": MODEL_COLORS["ours"], "vae": MODEL_COLORS["vae"], "neither": "#777777"}


def _diff_with_ci(ax, x, rows: pd.DataFrame, **style) -> None:
    """Mean Ours - VAE differences at x with their 95% CIs as error bars."""
    mean = rows["mean_diff"].to_numpy()
    yerr = [mean - rows["ci95_low"].to_numpy(), rows["ci95_high"].to_numpy() - mean]
    ax.errorbar(x, mean, yerr=yerr, fmt="none", ecolor=style.pop("ecolor", "black"),
                capsize=3, lw=1, zorder=2)
    ax.scatter(x, mean, zorder=3, edgecolor="black", linewidth=0.5, **style)


def plot_seed_pairs(per_seed: pd.DataFrame, family: pd.DataFrame, alpha: float,
                    base: Path) -> list[Path]:
    """Per world: each seed pair's Ours - VAE mean difference with its 95% CI, coloured by
    which model it favours at alpha, and the family (mean over seeds) beside them."""
    worlds = sorted(per_seed["world"].unique())
    fig, axes = plt.subplots(1, len(worlds), figsize=(4.6 * len(worlds), 4.0), squeeze=False)
    for ax, world in zip(axes[0], worlds, strict=True):
        pairs = per_seed[per_seed["world"] == world].sort_values("pair")
        fam = family[family["world"] == world]
        x = np.arange(len(pairs))
        _diff_with_ci(ax, x, pairs, s=30, c=[VERDICT_COLORS[v] for v in pairs["verdict"]])
        _diff_with_ci(ax, [len(pairs) + 0.6], fam, s=90, marker="D",
                      c=[VERDICT_COLORS[v] for v in fam["verdict"]], ecolor="#D55E00")
        ax.axhline(0, color="grey", lw=0.8, ls="--")
        labels = [f"{o}/{v}" for o, v in zip(pairs["ours_seed"], pairs["vae_seed"], strict=True)]
        ax.set_xticks([*x, len(pairs) + 0.6], [*labels, "family"], fontsize=7)
        ax.set_xlabel("seed pair (Ours seed / VAE seed)")
        counts = pairs["verdict"].value_counts()
        ax.set_title(f"{world}: pairs favouring Ours {counts.get('ours', 0)}, VAE "
                     f"{counts.get('vae', 0)}, neither {counts.get('neither', 0)}", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("err_ours - err_vae (< 0 favours Ours)")
    fig.suptitle(f"Per seed pair and family, 95% CI (colour: the model favoured at p < {alpha}, "
                 "grey: neither)", fontsize=9)
    fig.tight_layout()
    return save(fig, base)


def plot_leave_one_trial_out(table: pd.DataFrame, base: Path, top: int = 25) -> list[Path]:
    """Per world (columns) and set of answers (rows): the Ours - VAE mean difference with each
    of the `top` most influential main trials left out, beside the all-trials result."""
    worlds = sorted(table["world"].unique())
    answer_sets = list(dict.fromkeys(table["answers"]))
    shown = min(top, int(table.groupby(["world", "answers"]).size().max()))
    fig, axes = plt.subplots(len(answer_sets), len(worlds), squeeze=False,
                             figsize=(4.8 * len(worlds), (0.17 * shown + 1.4) * len(answer_sets)))
    for r, answers in enumerate(answer_sets):
        for c, world in enumerate(worlds):
            ax = axes[r][c]
            rows = table[(table["world"] == world) & (table["answers"] == answers)].head(top)
            y = np.arange(len(rows))[::-1]
            colors = np.where(rows["flips"], "#D55E00", "#333333")
            _trial_panel(ax, rows, y, colors)
            total = int(((table["world"] == world) & (table["answers"] == answers)).sum())
            ax.set_title(f"{world}, {answers} answers: the {len(rows)} most influential of "
                         f"{total} trials\n(red: leaving it out flips the verdict)", fontsize=8)
    fig.tight_layout()
    return save(fig, base)


def _trial_panel(ax, rows: pd.DataFrame, y: np.ndarray, colors: np.ndarray) -> None:
    """Horizontal: each trial's leave-one-out mean difference and CI; the all-trials mean."""
    mean = rows["mean_diff"].to_numpy()
    ax.errorbar(mean, y, xerr=[mean - rows["ci95_low"], rows["ci95_high"] - mean], fmt="none",
                ecolor="#999999", lw=0.8, capsize=2)
    ax.scatter(mean, y, c=colors, s=16, zorder=3)
    ax.axvline(rows["all_trials_mean_diff"].iloc[0], color="#0072B2", lw=1.2,
               label="all trials")
    ax.axvline(0, color="grey", lw=0.8, ls="--")
    ax.set_yticks(y, rows["trial_id"], fontsize=6)
    ax.set_xlabel("err_ours - err_vae without the trial (< 0 favours Ours)", fontsize=8)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(axis="x", alpha=0.3)


def plot_ceiling(worlds: dict, ceiling: dict, base: Path, reference: str = "") -> list[Path]:
    """Per world: each predictor's mean alignment error with its 95% CI beside the human
    noise ceiling (the band from its upper to its lower bound) and chance (1).

    `worlds` is summary["predictors"]["worlds"] ({world: {name: {mean, ci95}}}), `ceiling`
    summary["noise_ceiling"] ({world: {lower, upper, ...}}; a world may lack one); the
    `reference` predictor (the policy) is labelled as such."""
    names = list(worlds)
    rows = max(len(entry) for entry in worlds.values())
    fig, axes = plt.subplots(1, len(names), figsize=(4.8 * len(names), 0.45 * rows + 2.2),
                             squeeze=False)
    for ax, world in zip(axes[0], names, strict=True):
        _ceiling_panel(ax, worlds[world], ceiling.get(world), reference)
        ax.set_title(world[:1].upper() + world[1:], fontsize=10)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=8,
               frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return save(fig, base)


def _ceiling_panel(ax, predictors: dict, ceiling: dict | None, reference: str) -> None:
    """One world's panel: a row per predictor (first on top), the ceiling band, chance."""
    ax.axvline(1.0, color="grey", lw=0.8, ls="--", label="a random direction (chance)")
    y = np.arange(len(predictors))[::-1]
    for row, (name, entry) in zip(y, predictors.items(), strict=True):
        mean, (low, high) = entry["mean"], entry["ci95"]
        if low is not None and high is not None and np.isfinite([low, high]).all():
            ax.errorbar(mean, row, xerr=[[mean - low], [high - mean]], fmt="none",
                        ecolor="black", capsize=3, lw=1, zorder=2)
        ax.scatter(mean, row, s=40, color=model_color(name), edgecolor="black", zorder=3)
    labels = [model_label(n) + (" (reference)" if n == reference else "") for n in predictors]
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlim(left=0)
    if ceiling is not None:
        _ceiling_band(ax, ceiling["upper"], ceiling["lower"])
    ax.set_xlabel("alignment error (1 - cos): lower = closer to people", fontsize=8)
    ax.grid(axis="x", alpha=0.3)


def _ceiling_band(ax, upper: float, lower: float) -> None:
    """The noise ceiling from its upper to its lower bound (error), at least 1% of the axis
    wide so that a ceiling near 0 still shows; the lower bound as a line."""
    left, right = sorted((upper, lower))
    width = max(right - left, 0.01 * ax.get_xlim()[1])
    ax.axvspan(left, left + width, color="#bbbbbb", zorder=0,
               label="people predicting each other (noise ceiling, upper to lower bound)")
    ax.axvline(lower, color="#555555", lw=1, zorder=1)
