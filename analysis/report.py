"""`tomstudy analyze`: one command from exported predictions to a self-contained report.

Writes into the output folder: report.html (figures embedded as base64 PNG),
summary.json, per_participant.csv and by_start_kind.csv (every number the report shows),
the figures as PNG and SVG, and meta.json (data hash, checkpoint hashes, study config,
exclusions).
"""

import base64
import html
import json
import time
from pathlib import Path

import pandas as pd
import yaml
from tqdm import tqdm

from analysis.contracts import MODELS, ExclusionRules
from analysis.csvsafe import write_csv
from analysis.load import data_hash, load_csv
from analysis.metrics import (
    add_alignment_errors,
    apply_exclusions,
    participant_means,
    zero_vector_counts,
)
from analysis.plots import plot_errors, plot_fields
from analysis.stats import breakdown, compare_per_world, displacement_errors, mean_ci95

ALPHA = 0.01


def read_study_config(configs_dir: Path, study_id: str) -> dict:
    """The study's YAML as a plain mapping (analysis never imports the server's models)."""
    path = Path(configs_dir) / f"{study_id}.yaml"
    if not path.is_file():
        from app.configio import ConfigError

        raise ConfigError(f"{path}: study config not found")
    return yaml.safe_load(path.read_text()) or {}


def exclusion_rules(config: dict) -> ExclusionRules:
    """The study config's `exclusions` section, typed (a wrong key is an error naming it)."""
    from pydantic import ValidationError

    from app.configio import ConfigError, describe_validation_error

    try:
        return ExclusionRules.model_validate(config.get("exclusions") or {})
    except ValidationError as err:
        raise ConfigError(describe_validation_error(err, "exclusions")) from err


WAIVABLE = ("failed_attention_check", "incomplete", "too_fast")


def waive_rules(rules: ExclusionRules, waive: tuple[str, ...]) -> ExclusionRules:
    """The rules with the named ones switched off (a sensitivity analysis, reported as such)."""
    from app.configio import ConfigError

    unknown = [w for w in waive if w not in WAIVABLE]
    if unknown:
        raise ConfigError(f"waive: unknown rule(s) {', '.join(unknown)}; "
                          f"choose from {', '.join(WAIVABLE)}")
    changes: dict = {}
    for rule in waive:
        if rule == "too_fast":
            changes.update(too_fast_trial_ms=0.0, too_fast_max_fraction=1.0)
        else:
            changes[rule] = False
    return rules.model_copy(update=changes)


def checkpoint_hashes(config: dict, data_dir: Path) -> dict:
    """SHA-256 of each configured checkpoint file (None where the file is absent)."""
    from app.fileio import sha256_file

    hashes = {}
    for world, paths in (config.get("models") or {}).items():
        for model, rel in paths.items():
            path = Path(data_dir) / rel
            hashes[f"{world}/{model}"] = sha256_file(path) if path.is_file() else None
    return hashes


def load_scenes(data_dir: Path, study_id: str) -> tuple[dict, str | None]:
    """Each world's scene (JSON) from the trial bank (empty if there is no bank) and its hash."""
    from app.fileio import sha256_file

    path = Path(data_dir) / "trials" / study_id / "bank.json"
    if not path.is_file():
        return {}, None
    bank = json.loads(path.read_text())
    return {w: b["scene"] for w, b in bank["worlds"].items()}, sha256_file(path)


def world_summary(means: pd.DataFrame, ade: pd.DataFrame) -> dict:
    """Per world: n, mean error per model with 95% CI, ADE/FDE per model."""
    out = {}
    for world, group in means.groupby("world", sort=True):
        entry = {"n": int(len(group))}
        for model in MODELS:
            mean, low, high = mean_ci95(group[f"err_{model}"])
            entry[f"err_{model}"] = {"mean": mean, "ci95": [low, high]}
        disp = ade[ade["world"] == world]
        for col in [c for c in disp.columns if c.startswith(("ade_", "fde_"))]:
            entry[col] = float(disp[col].mean())
        out[world] = entry
    return out


def per_code(kept: pd.DataFrame) -> dict:
    """Per world and Ours code: trials, and mean error of Ours and the VAE on those rows."""
    out: dict = {}
    for (world, code), rows in kept.groupby(["world", "ours_code"], sort=True):
        out.setdefault(world, {})[str(code)] = {
            "trials": int(rows["trial_id"].nunique()), "rows": int(len(rows)),
            "err_ours": float(rows["err_ours"].mean()), "err_vae": float(rows["err_vae"].mean()),
            "err_policy": float(rows["err_policy"].mean())}
    return out


def start_kind_table(kept: pd.DataFrame) -> pd.DataFrame:
    """Per world x start_kind: n participants, mean error per model, Ours vs VAE paired test.

    Kinds are listed in the order the bank uses them (by mean start index: `own` first)."""
    table = breakdown(participant_means(kept, by=("start_kind",)), ["world", "start_kind"])
    rank = table["start_kind"].map(kept.groupby("start_kind")["start_index"].mean())
    return (table.assign(_rank=rank).sort_values(["world", "_rank", "start_kind"], kind="stable")
            .drop(columns="_rank").reset_index(drop=True))


def nested_by_kind(table: pd.DataFrame) -> dict:
    """The start-kind table as {world: {start_kind: {column: value}}}, NaN as null."""
    out: dict = {}
    for row in table.astype(object).where(table.notna(), None).to_dict("records"):
        out.setdefault(row.pop("world"), {})[row.pop("start_kind")] = row
    return out


def analyze(frame: pd.DataFrame, study_id: str, out_dir: Path, configs_dir: Path,
            data_dir: Path, source: str, waive: tuple[str, ...] = ()) -> dict:
    """Run the whole analysis on the export rows and write the report folder."""
    started = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    steps = tqdm(total=6, desc="analyze", unit="step")
    config = read_study_config(configs_dir, study_id)
    rules = waive_rules(exclusion_rules(config), waive)
    frame = frame[frame["study_id"] == study_id].reset_index(drop=True)
    if frame.empty:
        from app.configio import ConfigError

        raise ConfigError(f"study: no predictions for study {study_id!r} in {source}")
    digest = data_hash(frame)
    steps.update(1)
    exclusions = apply_exclusions(frame, rules)
    if exclusions.kept.empty:
        from app.configio import ConfigError

        raise ConfigError(f"exclusions: every participant was excluded {exclusions.counts()}; "
                          "a sensitivity analysis can waive a rule with --waive RULE")
    kept = add_alignment_errors(exclusions.kept)
    means = participant_means(kept)
    steps.update(1)
    results = compare_per_world(means, "ours", "vae")
    versus_cv = compare_per_world(means, "ours", "cv")
    ade = displacement_errors(kept)
    steps.update(1)
    scenes, bank_hash = load_scenes(data_dir, study_id)
    figures = plot_errors(means, results, out_dir / "alignment_error")
    figures += plot_fields(kept, scenes, out_dir / "fields")
    steps.update(1)
    per_participant = means.merge(ade, on=["participant_id", "world"], how="left")
    write_csv(per_participant, out_dir / "per_participant.csv", float_format="%.10g")
    by_kind = start_kind_table(kept)
    write_csv(by_kind, out_dir / "by_start_kind.csv", float_format="%.10g")
    summary = {
        "study_id": study_id, "source": source, "alpha": ALPHA,
        "exclusion_rules": rules.model_dump(), "waived_rules": list(waive),
        "exclusions": exclusions.counts(),
        "excluded_participants": exclusions.participants_excluded,
        "zero_vectors": zero_vector_counts(kept),
        "worlds": world_summary(means, ade),
        "ours_vs_vae": {w: r.as_dict() for w, r in results.items()},
        "ours_vs_cv": {w: r.as_dict() for w, r in versus_cv.items()},
        "per_ours_code": per_code(kept),
        "by_start_kind": nested_by_kind(by_kind),
        "hypothesis_supported": {w: bool(r.p_one_sided_less < ALPHA)
                                 for w, r in results.items()},
        "figures": sorted(p.name for p in figures),
    }
    write_outputs(out_dir, summary, figures, config, digest, data_dir, bank_hash, frame, started)
    steps.update(2)
    steps.close()
    return summary


def write_outputs(out_dir: Path, summary: dict, figures: list[Path], config: dict, digest: str,
                  data_dir: Path, bank_hash: str | None, frame: pd.DataFrame,
                  started: float) -> None:
    """summary.json, report.html and meta.json."""
    from app.fileio import write_json

    write_json(out_dir / "summary.json", summary)
    (out_dir / "report.html").write_text(render_html(summary, [f for f in figures
                                                              if f.suffix == ".png"]))
    hashes_in_data = {m: sorted(set(frame[f"{m}_sha256"])) for m in ("ours", "vae")}
    write_json(out_dir / "meta.json", {
        "data_sha256": digest, "rows": len(frame), "source": summary["source"],
        "checkpoint_sha256": checkpoint_hashes(config, data_dir),
        "model_hashes_in_data": hashes_in_data, "trial_bank_sha256": bank_hash,
        "study_config": config, "wall_time_s": round(time.perf_counter() - started, 3),
        "package_version": _version(),
    })


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tomstudy")
    except PackageNotFoundError:
        return "unknown"


def _fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1e-3 and value != 0 else f"{value:.{digits}f}"
    return html.escape(str(value))


KIND_HEAD = "".join(f"<th>{h}</th>" for h in (
    "world", "start kind", "n", "Ours", "VAE", "const. vel.", "policy",
    "Ours - VAE [95% CI]", "t", "p (Ours &lt; VAE)", "Wilcoxon p", "d_z"))


def kind_rows(by_kind: dict) -> str:
    """HTML rows of the start-kind table: mean errors and the paired Ours vs VAE test."""
    rows = []
    for world, kinds in by_kind.items():
        for kind, r in kinds.items():
            rows.append(
                f"<tr><td>{html.escape(world)}</td><td>{html.escape(kind)}</td><td>{r['n']}</td>"
                + "".join(f"<td>{_fmt(r[f'err_{m}'])}</td>" for m in MODELS)
                + f"<td>{_fmt(r['mean_diff'])} [{_fmt(r['ci95_low'])}, {_fmt(r['ci95_high'])}]"
                f"</td><td>{_fmt(r['t'])}</td><td>{_fmt(r['p_one_sided_less'])}</td>"
                f"<td>{_fmt(r['wilcoxon_p'])}</td><td>{_fmt(r['d_z'])}</td></tr>")
    return "".join(rows)


def render_html(summary: dict, pngs: list[Path]) -> str:
    """The report page: tables of every test and mean, exclusions, embedded figures."""
    rows = []
    for world, res in summary["ours_vs_vae"].items():
        w = summary["worlds"][world]
        rows.append(
            f"<tr><td>{html.escape(world)}</td><td>{res['n']}</td>"
            + "".join(f"<td>{_fmt(w[f'err_{m}']['mean'])} [{_fmt(w[f'err_{m}']['ci95'][0])}, "
                      f"{_fmt(w[f'err_{m}']['ci95'][1])}]</td>" for m in MODELS)
            + f"<td>{_fmt(res['mean_diff'])} [{_fmt(res['ci95_low'])}, {_fmt(res['ci95_high'])}]"
            f"</td><td>{_fmt(res['t'])}</td><td>{_fmt(res['p_two_sided'])}</td>"
            f"<td>{_fmt(res['p_one_sided_less'])}</td><td>{_fmt(res['wilcoxon_p'])}</td>"
            f"<td>{_fmt(res['d_z'])}</td>"
            f"<td>{'yes' if summary['hypothesis_supported'][world] else 'no'}</td></tr>")
    disp = []
    for world, w in summary["worlds"].items():
        disp.append(f"<tr><td>{html.escape(world)}</td>" + "".join(
            f"<td>{_fmt(w.get(f'{k}_{m}'))}</td>" for m in ("ours", "vae", "cv")
            for k in ("ade", "fde")) + "</tr>")
    kinds = kind_rows(summary["by_start_kind"])
    excl = "".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>"
                   for k, v in summary["exclusions"].items())
    waived = html.escape(", ".join(summary["waived_rules"]) or "none")
    zero = ", ".join(f"{k}: {v}" for k, v in summary["zero_vectors"].items())
    images = "".join(
        f"<figure><img alt='{html.escape(p.stem)}' src='data:image/png;base64,"
        f"{base64.b64encode(p.read_bytes()).decode()}'><figcaption>{html.escape(p.name)}"
        "</figcaption></figure>" for p in pngs)
    head = "".join(f"<th>{h}</th>" for h in (
        "world", "n", "Ours", "VAE", "const. vel.", "policy", "Ours - VAE [95% CI]", "t",
        "p (two-sided)", "p (Ours &lt; VAE)", "Wilcoxon p", "d_z", f"p &lt; {ALPHA}"))
    dhead = "".join(f"<th>{m} {k}</th>" for m in ("Ours", "VAE", "CV") for k in ("ADE", "FDE"))
    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>tomstudy report: {html.escape(summary['study_id'])}</title>
<style>body{{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:4px 8px;
font-size:13px;text-align:right}}img{{max-width:100%}}figure{{margin:1.5em 0}}</style>
</head><body><h1>Study {html.escape(summary['study_id'])}: does Ours predict what people
predict better than the VAE?</h1>
<p>Source: {html.escape(summary['source'])}. Alignment error = 1 - cos(angle) between a
participant's action and a model's action at the same start state and step (0 = same
direction, 2 = opposite), averaged per participant and world; paired tests across
participants.</p>
<h2>Mean alignment error per world (mean [95% CI]) and Ours vs VAE</h2>
<table><tr>{head}</tr>{''.join(rows)}</table>
<h2>By start kind (own = the robot's segment end; others drawn from the data near it)</h2>
<table><tr>{KIND_HEAD}</tr>{kinds}</table>
<h2>Displacement from the clicked positions [m]</h2><table><tr><th>world</th>{dhead}</tr>
{''.join(disp)}</table>
<h2>Exclusions</h2><p>Waived rules (sensitivity analysis): {waived}.</p><table>{excl}</table>
<p>Actions shorter than 1e-6 m/s (alignment error defined as 1): {html.escape(zero)}.</p>
<h2>Figures</h2>{images}
<p>Every number above is in summary.json and per_participant.csv next to this file.</p>
</body></html>
"""


def run_analyze(study_id: str, out_dir: Path, csv: Path | None, database_url: str,
                configs_dir: Path, data_dir: Path, waive: tuple[str, ...] = ()) -> dict:
    """Load from the CSV (if given) or the database, analyse, print the headline numbers."""
    from analysis.load import load_database

    if csv is not None:
        frame, source = load_csv(csv), f"csv {csv}"
    else:
        frame, source = load_database(database_url, study_id), "database"
    summary = analyze(frame, study_id, out_dir, configs_dir, data_dir, source, waive)
    for world, res in summary["ours_vs_vae"].items():
        w = summary["worlds"][world]
        print(f"{world}: n={res['n']} Ours {w['err_ours']['mean']:.3f} VAE "
              f"{w['err_vae']['mean']:.3f} CV {w['err_cv']['mean']:.3f} | t={res['t']:.2f} "
              f"p={res['p_two_sided']:.2g} (one-sided {res['p_one_sided_less']:.2g}) "
              f"d_z={res['d_z']:.2f}")
    print(f"wrote {Path(out_dir) / 'report.html'}")
    return summary
