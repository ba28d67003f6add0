"""`tomstudy analyze`: one command from exported predictions to a self-contained report.

Writes into the output folder: report.html (analysis/templates/study_report.html.j2,
figures embedded as base64 PNG), summary.json, per_participant.csv, by_start_kind.csv,
per_seed.csv, family.csv, by_arm.csv, mixed_model.csv, leave_one_trial_out.csv,
predictors.csv and pairwise.csv (every number the report shows), the figures as PNG and SVG,
and meta.json (data and bank hashes, the model family's content hashes, study config). The
study config is read by the caller (app/bank/served.py) and arrives as plain values and paths
(`StudyInputs`).

Besides the primary answers (the primary seed's, in the export), the report reads every
seed's answers from the trial bank (analysis/seeds.py) and treats trials as a random factor
(analysis/trial_effects.py); both, and the per-arm comparison, run on the same kept rows, as
does the comparison of every predictor (plug-ins too) with the people (analysis/predictors.py).
"""

import time
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from analysis.bank import Bank, family_hashes, read_bank
from analysis.ceiling import ceiling_table, explainable_share
from analysis.crossed import primary_table
from analysis.direct import direct_summary, direct_table
from analysis.html import render_page
from analysis.load import data_hash, load_csv
from analysis.metrics import (
    add_alignment_errors,
    apply_exclusions,
    participant_means,
    zero_vector_counts,
)
from analysis.plots import (
    plot_ceiling,
    plot_errors,
    plot_fields,
    plot_leave_one_trial_out,
    plot_seed_pairs,
)
from analysis.predictors import (
    FAMILY,
    REFERENCE,
    pairwise_table,
    predictor_means,
    predictor_names,
    primary_fits,
    world_means,
)
from analysis.seeds import seed_results, verdict_counts
from analysis.stats import (
    ALPHA,
    breakdown,
    by_arm_table,
    compare_per_world,
    displacement_errors,
    mean_ci95,
    plain_records,
)
from analysis.trial_effects import influence_summary, leave_one_trial_out, mixed_model_table
from analysis.verdicts import (
    EXPLORATORY_KEY,
    direct_sentences,
    fmt,
    fmt_p,
    primary_sentence,
    primary_sentences,
)
from app.core.contracts import (
    MODELS,
    SMALLEST_EFFECT_OF_INTEREST,
    ExclusionRules,
    StudyInputs,
)
from app.core.csvsafe import write_csv
from app.core.files import write_json

WAIVABLE = ("failed_attention_check", "incomplete", "too_fast")


class AnalysisError(ValueError):
    """The analysis cannot run as asked; the message names the option or says why."""


def waive_rules(rules: ExclusionRules, waive: tuple[str, ...]) -> ExclusionRules:
    """The rules with the named ones switched off (a sensitivity analysis, reported as such)."""
    unknown = [w for w in waive if w not in WAIVABLE]
    if unknown:
        raise AnalysisError(f"waive: unknown rule(s) {', '.join(unknown)}; "
                            f"choose from {', '.join(WAIVABLE)}")
    changes: dict = {}
    for rule in waive:
        if rule == "too_fast":
            changes.update(too_fast_trial_ms=0.0, too_fast_max_fraction=1.0)
        else:
            changes[rule] = False
    return rules.model_copy(update=changes)


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


def nested(table: pd.DataFrame, keys: list[str]) -> dict:
    """A table as nested dicts, one level per key column (e.g. {world: {start_kind: row}}),
    NaN as null."""
    out: dict = {}
    for row in plain_records(table):
        node = out
        for key in keys[:-1]:
            node = node.setdefault(str(row.pop(key)), {})
        node[str(row.pop(keys[-1]))] = row
    return out


def robustness(kept: pd.DataFrame, bank: Bank | None, inputs: StudyInputs,
               out_dir: Path) -> tuple[dict, list[Path], pd.DataFrame]:
    """The pre-registered primary test, per seed pair and family, per arm, the crossed mixed
    model and leave-one-trial-out: their summary.json entries, CSVs and figures, and the mixed
    models' table (every_predictor reuses its fits). 'primary' answers are the export's (the
    primary seed's) on every kept row; 'family' the mean over seeds on the rows that ran the
    bank."""
    seeds = seed_results(kept, bank, str(inputs.bank))
    answer_sets = {"primary": kept} | ({"family": seeds.family_rows} if seeds.ok else {})
    tables = {"per_seed": seeds.per_seed, "family": seeds.family,
              "by_arm": by_arm_table(answer_sets), "mixed_model": mixed_model_table(answer_sets),
              "leave_one_trial_out": leave_one_trial_out(answer_sets)}
    for name, table in tables.items():
        if not table.empty:
            write_csv(table, out_dir / f"{name}.csv", float_format="%.10g")
    figures = plot_seed_pairs(seeds.per_seed, seeds.family, ALPHA,
                              out_dir / "seed_pairs") if seeds.ok else []
    figures += plot_leave_one_trial_out(tables["leave_one_trial_out"],
                                        out_dir / "leave_one_trial_out")
    summary = {
        "seeds": seeds.join,
        "per_seed": nested(seeds.per_seed, ["world", "pair"]) if seeds.ok else {},
        "seed_pair_verdicts": verdict_counts(seeds.per_seed) if seeds.ok else {},
        "family": nested(seeds.family, ["world"]) if seeds.ok else {},
        "by_arm": nested(tables["by_arm"], ["world", "arm", "answers"]),
        "mixed_model": nested(tables["mixed_model"], ["world", "arm", "answers"]),
        "leave_one_trial_out": influence_summary(tables["leave_one_trial_out"]),
        "primary": preregistered_primary(seeds.family_rows if seeds.ok else None,
                                         inputs.config.get("exploratory_worlds") or {},
                                         smallest_effect(inputs.config), out_dir),
    }
    return summary, figures, tables["mixed_model"]


def noise_ceiling(kept: pd.DataFrame, out_dir: Path) -> dict:
    """The human noise ceiling per world (ceiling.csv) with every predictor's share of it (the
    models, the baselines, the observers and any plug-in)."""
    table = ceiling_table(kept)
    if table.empty:
        return {}
    write_csv(table, out_dir / "ceiling.csv", float_format="%.10g")
    out = nested(table, ["world"])
    names = tuple(c.removeprefix("err_") for c in kept.columns if c.startswith("err_"))
    means = participant_means(kept, names)
    for world, entry in out.items():
        errors = means[means["world"] == world]
        shares = {m: explainable_share(float(errors[f"err_{m}"].mean()), entry["lower"],
                                       entry["lower_ci95_high"])
                  for m in names}
        entry["share"] = {m: None if np.isnan(v) else v for m, v in shares.items()}
    return out


def smallest_effect(config: dict) -> float:
    """The study's smallest effect of interest (a config at the default leaves it out)."""
    return float(config.get("smallest_effect_of_interest", SMALLEST_EFFECT_OF_INTEREST))


def direct_test(kept: pd.DataFrame, exploratory: dict[str, str], out_dir: Path) -> dict:
    """The direct test of the claim per world (analysis/direct.py), written to direct.csv;
    {} where the export holds no observer's answers."""
    table = direct_table(kept, ALPHA, exploratory)
    if table.empty:
        return {}
    write_csv(table, out_dir / "direct.csv", float_format="%.10g")
    return direct_summary(table)


def preregistered_primary(family_rows: pd.DataFrame | None, exploratory: dict[str, str],
                          sesoi: float, out_dir: Path) -> dict:
    """The pre-registered primary test (family, participants and trials random, min F') per
    world with the evidence for a null beside it, written to primary.csv; {} without the
    family's rows."""
    if family_rows is None:
        return {}
    table = primary_table(family_rows, ALPHA, exploratory, sesoi)
    write_csv(table, out_dir / "primary.csv", float_format="%.10g")
    return nested(table, ["world"]) | {"exploratory_worlds": exploratory}


def every_predictor(kept: pd.DataFrame, mixed_model: pd.DataFrame,
                    out_dir: Path) -> tuple[dict, list[Path]]:
    """Every predictor against the people (analysis/predictors.py): predictors.csv (per
    participant and world), pairwise.csv, the side-by-side figure and their summary entry.
    Ours vs the VAE takes its mixed model from robustness's table (`mixed_model`)."""
    names = predictor_names(kept.columns)
    means = predictor_means(kept, names)
    pairwise = pairwise_table(kept, names, means, primary_fits(mixed_model))
    write_csv(means, out_dir / "predictors.csv", float_format="%.10g")
    write_csv(pairwise, out_dir / "pairwise.csv", float_format="%.10g")
    figures = plot_errors(means, {}, out_dir / "predictors", models=(*names, REFERENCE))
    return {"names": names, "reference": REFERENCE, "family": FAMILY, "alpha": ALPHA,
            "worlds": world_means(means, names),
            "pairwise": nested(pairwise, ["world", "pair"])}, figures


def analyze(frame: pd.DataFrame, study_id: str, out_dir: Path, inputs: StudyInputs,
            source: str, waive: tuple[str, ...] = ()) -> dict:
    """Run the whole analysis on the export rows and write the report folder."""
    started = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    steps = tqdm(total=7, desc="analyze", unit="step")
    rules = waive_rules(inputs.rules, waive)
    frame = frame[frame["study_id"] == study_id].reset_index(drop=True)
    if frame.empty:
        raise AnalysisError(f"study: no predictions for study {study_id!r} in {source}")
    digest = data_hash(frame)
    steps.update(1)
    exclusions = apply_exclusions(frame, rules)
    if exclusions.kept.empty:
        raise AnalysisError(f"exclusions: every participant was excluded {exclusions.counts()}; "
                            "a sensitivity analysis can waive a rule with --waive RULE")
    kept = add_alignment_errors(exclusions.kept)
    means = participant_means(kept)
    steps.update(1)
    results = compare_per_world(means, "ours", "vae")
    versus_cv = compare_per_world(means, "ours", "cv")
    ade = displacement_errors(kept)
    steps.update(1)
    bank = read_bank(inputs.bank)
    extra, extra_figures, mixed_model = robustness(kept, bank, inputs, out_dir)
    extra["noise_ceiling"] = noise_ceiling(kept, out_dir)
    extra["direct"] = direct_test(kept, inputs.config.get("exploratory_worlds") or {}, out_dir)
    steps.update(1)
    predictors, predictor_figures = every_predictor(kept, mixed_model, out_dir)
    figures = plot_errors(means, results, out_dir / "alignment_error") + extra_figures
    figures += predictor_figures
    if extra["noise_ceiling"]:
        figures += plot_ceiling(predictors["worlds"], extra["noise_ceiling"],
                                out_dir / "noise_ceiling", reference=REFERENCE)
    figures += plot_fields(kept, bank.scenes() if bank else {}, out_dir / "fields")
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
        "by_start_kind": nested(by_kind, ["world", "start_kind"]),
        "hypothesis_supported": {w: bool(r.p_one_sided_less < ALPHA)
                                 for w, r in results.items()},
        **extra,
        "predictors": predictors,
        "figures": sorted(p.name for p in figures),
    }
    write_outputs(out_dir, summary, figures, inputs, digest, bank, frame, started)
    steps.update(2)
    steps.close()
    return summary


def write_outputs(out_dir: Path, summary: dict, figures: list[Path], inputs: StudyInputs,
                  digest: str, bank: Bank | None, frame: pd.DataFrame, started: float) -> None:
    """summary.json, report.html and meta.json."""
    write_json(out_dir / "summary.json", summary)
    (out_dir / "report.html").write_text(render_html(summary, [f for f in figures
                                                              if f.suffix == ".png"]))
    hashes_in_data = {m: sorted(set(frame[f"{m}_sha256"])) for m in ("ours", "vae")}
    write_json(out_dir / "meta.json", {
        "data_sha256": digest, "rows": len(frame), "source": summary["source"],
        "models": inputs.models, **bank_models(bank, inputs.models),
        "model_hashes_in_data": hashes_in_data,
        "trial_bank_sha256": bank.sha256 if bank else None,
        "trial_bank_path": str(inputs.bank),
        "study_config": inputs.config, "wall_time_s": round(time.perf_counter() - started, 3),
        "package_version": _version(),
    })


def bank_models(bank: Bank | None, models: dict) -> dict:
    """The content hashes of the answers the bank stores, and whether they are the models the
    study names (None without a bank or without models to compare)."""
    in_bank = family_hashes(bank.data) if bank else None
    same = in_bank == models if (in_bank is not None and models) else None
    return {"models_in_bank": in_bank, "models_match_bank": same}


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tomstudy")
    except PackageNotFoundError:
        return "unknown"


def render_html(summary: dict, pngs: list[Path]) -> str:
    """The report page: first the answer (the primary test per world in words, the direct
    test, every predictor against the noise ceiling), then every table and figure in Details."""
    primary = {world: entry for world, entry in summary.get("primary", {}).items()
               if world != EXPLORATORY_KEY}
    return render_page("study_report.html.j2", filters={"fmt": fmt}, s=summary, alpha=ALPHA,
                       models=MODELS, figures=figure_sections(pngs), page_width_px=1200,
                       answers=primary_sentences(primary), primary_rows=primary,
                       equivalence=any("conclusion" in entry for entry in primary.values()),
                       direct=direct_sentences(summary.get("direct", {})))


# Each figure's place in the report and its caption: what is plotted, what lower or higher means
FIGURES = {
    "noise_ceiling": ("answer", "Every predictor against how well people predict each other",
                      "Per world, each predictor's mean alignment error with the participants' "
                      "predictions (dot: mean over participants, bar: 95% CI). Alignment error "
                      "is 1 - cos of the angle between a predictor's move and a participant's: "
                      "0 is the same direction, 1 what a random direction scores (dashed line), "
                      "2 the opposite; lower is closer to what people predict. The grey band is "
                      "the human noise ceiling, from its upper bound (each participant against "
                      "everyone's mean move, their own included) to its lower bound (against "
                      "the other participants' mean): a predictor inside the band predicts "
                      "people about as well as people predict each other."),
    "alignment_error": ("primary_seed", "Alignment error of Ours, the VAE and constant velocity",
                        "Per world, the alignment error (1 - cos) of Ours, the VAE and constant "
                        "velocity with the primary seed's answers: one dot per participant (their "
                        "mean), grey lines join one participant's values, black the mean with "
                        "its 95% CI. Lower is closer to what people predict. The panel titles "
                        "give the paired t-test of Ours vs the VAE (two-sided p)."),
    "predictors": ("predictors", "Alignment error of every predictor",
                   "Per world, every predictor's alignment error (1 - cos): one dot per "
                   "participant (their mean), grey lines join one participant's values, black "
                   "the mean with its 95% CI; the policy (the world's own moves) is a "
                   "reference. Lower is closer to what people predict."),
    "seed_pairs": ("families", "Ours - VAE per seed pair and for the family",
                   "Per world, Ours' alignment error minus the VAE's for each pair of training "
                   "seeds (dots) and for the family, the mean over seeds (diamond), with 95% "
                   "CIs. Below 0 people's predictions align better with Ours, above 0 with the "
                   "VAE. Colour: the model a two-sided paired test favours at p < {alpha} (grey: "
                   "neither)."),
    "leave_one_trial_out": ("influence", "Ours - VAE with each influential trial left out",
                            "Per world and set of answers, the Ours - VAE difference in "
                            "alignment error with one trial left out (dot and 95% CI, the most "
                            "influential trials first), beside the difference over all trials "
                            "(blue line). Left of 0 favours Ours, right of 0 the VAE; red: "
                            "leaving that trial out changes the verdict."),
    "fields": ("fields", "Participants' first moves beside each model's",
               "{world}: at each start state, the participants' mean first move (black arrow) "
               "beside a model's (colour), for each model's most common latent codes. Arrows "
               "pointing the same way mean the model predicts what people predict; each panel "
               "gives the model's mean alignment error there (lower is closer)."),
}


def figure_sections(pngs: list[Path]) -> dict[str, list[dict]]:
    """The report's figures by section (FIGURES), each with its alt text and caption; a
    figure FIGURES does not know goes to 'other', captioned by its name."""
    out: dict[str, list[dict]] = {}
    for png in pngs:
        stem, _, world = png.stem.partition("_") if png.stem.startswith("fields_") else (
            png.stem, "", "")
        section, alt, caption = FIGURES.get(stem, ("other", png.stem, png.name))
        out.setdefault(section, []).append(
            {"path": png, "alt": f"{alt}: {world}" if world else alt,
             "caption": caption.format(world=world[:1].upper() + world[1:], alpha=ALPHA)})
    return out


def run_analyze(study_id: str, out_dir: Path, csv: Path | None, database_url: str,
                inputs: StudyInputs, waive: tuple[str, ...] = ()) -> dict:
    """Load from the CSV (if given) or the database, analyse, print the headline numbers."""
    from analysis.load import load_database

    if csv is not None:
        frame, source = load_csv(csv), f"csv {csv}"
    else:
        frame, source = load_database(database_url, study_id), "database"
    summary = analyze(frame, study_id, out_dir, inputs, source, waive)
    print("\n".join(headline(summary)))
    print(f"wrote {Path(out_dir) / 'report.html'}")
    return summary


def headline(summary: dict) -> list[str]:
    """The lines `analyze` prints: per world the primary test, the family's and the trials'."""
    lines = []
    for world, res in summary["ours_vs_vae"].items():
        if world in summary.get("primary", {}):
            lines.append(primary_sentence(world, summary["primary"][world]))
            lines.append("  " + _primary_line(world, summary["primary"][world]))
        w = summary["worlds"][world]
        lines.append(f"{world}: n={res['n']} Ours {w['err_ours']['mean']:.3f} VAE "
                     f"{w['err_vae']['mean']:.3f} CV {w['err_cv']['mean']:.3f} | "
                     f"t={res['t']:.2f} p={res['p_two_sided']:.2g} (one-sided "
                     f"{res['p_one_sided_less']:.2g}) d_z={res['d_z']:.2f}")
        if world in summary["family"]:
            lines.append(_family_line(summary["family"][world],
                                      summary["seed_pair_verdicts"][world]))
        lines.append(_trials_line(summary["mixed_model"][world]["pooled"]["primary"],
                                  summary["leave_one_trial_out"][world]["primary"]))
        lines.append(_predictors_line(summary["predictors"], world))
        if world in summary.get("noise_ceiling", {}):
            lines.append(_ceiling_line(summary["noise_ceiling"][world]))
        if world in summary.get("direct", {}):
            lines.append(_direct_line(summary["direct"][world]))
    seeds = summary["seeds"]
    if seeds["status"] != "ok" or seeds["other_banks"] or seeds["rows_not_in_bank"]:
        lines.append(f"per seed: {seeds['note']}")
    return lines


def _ceiling_line(ceiling: dict) -> str:
    shares = ", ".join(f"{m} {fmt(v, 2)}" for m, v in ceiling["share"].items())
    return (f"  noise ceiling (people predicting each other): lower {fmt(ceiling['lower'])}, "
            f"upper {fmt(ceiling['upper'])}, split-half r {fmt(ceiling['split_half_r'], 2)}; "
            f"share of the explainable alignment: {shares}")


def _direct_line(direct: dict) -> str:
    tests = "; ".join(f"{name} {fmt(v['mean_diff'])} [{fmt(v['ci95_low'])}, "
                      f"{fmt(v['ci95_high'])}] p_holm={fmt_p(v['p_holm'])} {v['verdict']}"
                      for name, v in direct["variants"].items())
    return (f"  direct test (each coarse observer - the precise one, participants and trials "
            f"random, Holm): {tests} -> {direct['verdict']}")


def _ratio(value: float | None) -> str:
    """A Bayes factor in three significant digits (they span many orders), None as '-'."""
    return "-" if value is None else f"{value:.3g}"


def _primary_line(world: str, res: dict) -> str:
    kind = "EXPLORATORY, not a test of the hypothesis" if res["exploratory"] else "primary"
    return (f"{world} ({kind}): family Ours - VAE {fmt(res['mean_diff'])} "
            f"[{fmt(res['ci95_low'])}, {fmt(res['ci95_high'])}], participants and "
            f"trials random (min F'({fmt(res['df'], 1)}) = {fmt(res['min_f'], 2)}, p = "
            f"{fmt_p(res['p_two_sided'])}; {res['n_participants']} participants, "
            f"{res['n_trials']} trials) -> {res['verdict']}; within +-{fmt(res['sesoi'])}: "
            f"TOST p = {fmt_p(res['tost_p'])}, BF10 = {_ratio(res['bf10'])} -> "
            f"{res['conclusion']}")


def _predictors_line(predictors: dict, world: str) -> str:
    means = ", ".join(f"{name} {fmt(entry['mean'])}"
                      for name, entry in predictors["worlds"][world].items())
    lower = [f"{r['verdict']} < {r['b'] if r['verdict'] == r['a'] else r['a']}"
             for r in predictors["pairwise"][world].values() if r["verdict"] != "neither"]
    return (f"  every predictor: {means} ({REFERENCE}: reference); Holm p < "
            f"{predictors['alpha']}: {', '.join(lower) or 'no pair'}")


def _family_line(fam: dict, pairs: dict) -> str:
    return (f"  family ({fam['ours_seeds']} Ours x {fam['vae_seeds']} VAE seeds): Ours "
            f"{fmt(fam['err_ours'])} VAE {fmt(fam['err_vae'])} | diff {fmt(fam['mean_diff'])} "
            f"t={fmt(fam['t'], 2)} p={fmt_p(fam['p_two_sided'])} -> {fam['verdict']}; seed "
            f"pairs favour Ours {pairs['ours']}, VAE {pairs['vae']}, neither {pairs['neither']}")


def _trials_line(mixed: dict, influence: dict) -> str:
    top = influence["most_influential"]
    flips = ", ".join(influence["flipping_trials"]) or "none"
    return (f"  trials as random: diff {fmt(mixed['estimate'])} [{fmt(mixed['ci95_low'])}, "
            f"{fmt(mixed['ci95_high'])}] p={fmt_p(mixed['p'])} ({mixed['status']}); without "
            f"{top['trial_id']} the diff moves most ({fmt(top['shift'])}); flips: {flips}")
