"""The researcher dashboard's read side: sessions, study versions, live alignment and fields.

Numbers come from the analysis package on the export rows (the same exclusion rules,
per-participant means, t intervals and field tables as `tomstudy analyze`); this module
only selects rows and shapes JSON for the browser. Replays are in app/researcher/replay.py.
"""

import math
from datetime import datetime

import numpy as np
import pandas as pd
from sqlalchemy import func, select
from sqlmodel import Session

from app import __version__
from app.researcher.exports import checks_answered, predictions_frame
from app.researcher.pay import time_and_pay
from app.researcher.progress import (
    every_predictor,
    exclusion_rules,
    progress_counts,
    study_sessions,
)
from app.server.queries import (
    Cutoffs,
    Participant,
    StudyContext,
    as_utc,
    codes_table,
    progress_of,
    session_status,
    status_cutoffs,
)
from app.study.config import stored_predictors

FIELD_CODES = 3  # most common codes per model, as the report's figures


def _iso(moment: datetime | None) -> str | None:
    return as_utc(moment).isoformat() if moment else None


def _finite(value: float) -> float | None:
    """JSON has no NaN: an undefined number (a CI of one participant) is null."""
    return float(value) if value is not None and math.isfinite(value) else None


# ---------------------------------------------------------------- sessions

def participant_row(p: Participant, ctx: StudyContext, cutoffs: Cutoffs, checks_seen: int,
                    external_ids: bool) -> dict:
    """One session as the table shows it (the external id only when asked for)."""
    end = p.ended_at or p.updated_at
    row = {
        "public_id": p.public_id, "platform": p.recruitment, "pilot": p.pilot,
        "status": session_status(p, cutoffs),
        "outcome": p.outcome,
        "started_at": _iso(p.created_at), "last_seen": _iso(p.updated_at),
        "ended_at": _iso(p.ended_at), "world_order": p.world_order,
        "attention": {"failed": p.attention_failed, "seen": checks_seen},
        "duration_s": round((as_utc(end) - as_utc(p.created_at)).total_seconds(), 1),
        "progress": progress_of(p),
        "config_current": p.config_sha256 == ctx.config_sha256,
        "bank_current": p.bank_sha256 == ctx.bank.sha256,
    }
    if external_ids:
        row["external_id"] = p.external_id
    return row


def participant_rows(db: Session, ctx: StudyContext, people: list[Participant],
                     external_ids: bool = False) -> list[dict]:
    """Every session of the study (progress.study_sessions: pilots and replaced ones
    included, in order of start) as the table shows it."""
    cutoffs = status_cutoffs(ctx.config)
    seen = checks_answered(db, ctx.study_id)
    return [participant_row(p, ctx, cutoffs, seen.get(p.id, 0), external_ids) for p in people]


# ---------------------------------------------------------------- versions

def hash_counts(db: Session, study_id: str, column) -> dict[str, int]:
    """Sessions per stored hash ('' = stored before the hashes were)."""
    query = (select(column, func.count()).where(Participant.study_id == study_id)
             .group_by(column))
    return {sha or "": n for sha, n in db.execute(query).all()}


def versions(db: Session, ctx: StudyContext) -> dict:
    """Sessions per config and bank hash, and a warning when any ran other than the loaded."""
    out: dict = {"app_version": __version__, "warnings": []}
    loaded = {"config": ctx.config_sha256, "bank": ctx.bank.sha256}
    columns = {"config": Participant.config_sha256, "bank": Participant.bank_sha256}
    for what, column in columns.items():
        counts = hash_counts(db, ctx.study_id, column)
        out[what] = {"loaded": loaded[what], "sessions": [
            {"sha256": sha, "sessions": n, "loaded": sha == loaded[what]}
            for sha, n in sorted(counts.items(), key=lambda kv: (kv[0] != loaded[what], kv[0]))]}
        other = sum(n for sha, n in counts.items() if sha != loaded[what])
        if other:
            out["warnings"].append(
                f"{other} of {sum(counts.values())} sessions ran under a {what} other than the "
                f"one this server has loaded ({loaded[what][:12]}): compare their numbers "
                f"with care")
    return out


# ---------------------------------------------------------------- alignment

def kept_rows(frame: pd.DataFrame, ctx: StudyContext, rule_set: str) -> tuple[pd.DataFrame, dict]:
    """The rows the analysis keeps (of predictions_frame's, already normalised), with
    alignment errors, and what each rule removed."""
    from analysis.metrics import add_alignment_errors, apply_exclusions

    result = apply_exclusions(frame, exclusion_rules(ctx, rule_set))
    return add_alignment_errors(result.kept), result.counts()


def world_errors(kept: pd.DataFrame, names: list[str]) -> dict:
    """Per world and predictor in `names`: mean of per-participant means, its 95% t interval,
    the means."""
    from analysis.metrics import participant_means
    from analysis.stats import compare_per_world, mean_ci95

    if kept.empty:
        return {}
    means = participant_means(kept, tuple(names))
    paired = compare_per_world(means, "ours", "vae")
    out = {}
    for world, group in means.groupby("world", sort=True):
        models = {}
        for model in names:
            values = group[f"err_{model}"].to_numpy()
            mean, low, high = mean_ci95(values)
            models[model] = {"mean": _finite(mean), "ci95": [_finite(low), _finite(high)],
                             "participants": [round(float(v), 5) for v in values]}
        test = paired[world]
        out[world] = {"n": int(len(group)), "models": models, "ours_vs_vae": {
            k: _finite(getattr(test, k))
            for k in ("mean_diff", "ci95_low", "ci95_high", "t", "p_two_sided", "d_z")}}
    return out


def world_fields(kept: pd.DataFrame, ctx: StudyContext, k: int = FIELD_CODES) -> dict:
    """Per world, the report's field panels: for Ours' and the VAE's k most common codes,
    each start state's position, participants' mean first move and the model's (unit)."""
    from analysis.fields import FIELD_MODELS, arrow_length, code_panels, state_table

    out = {}
    for world in sorted(kept["world"].unique()) if len(kept) else []:
        scene = ctx.bank.world(world).scene
        states_w = state_table(kept[kept["world"] == world])
        arrow_m = arrow_length(scene)
        panels = [_panel(model, code, states, arrow_m)
                  for model in FIELD_MODELS for code, states in code_panels(states_w, model, k)]
        out[world] = {"scene": scene, "arrow_m": arrow_m, "panels": panels,
                      "x_range_m": [float(states_w["x"].min()), float(states_w["x"].max())]}
    return out


def _panel(model: str, code: int, states: pd.DataFrame, arrow_m: float) -> dict:
    from analysis.fields import panel_error, unit

    hx, hy = unit(states["participant_vx"].to_numpy(), states["participant_vy"].to_numpy())
    mx, my = unit(states[f"{model}_vx"].to_numpy(), states[f"{model}_vy"].to_numpy())
    points = np.column_stack([states["x"], states["y"], hx, hy, mx, my]).round(4)
    return {"model": model, "code": int(code), "trials": int(states["trial_id"].nunique()),
            "error": _finite(panel_error(states, model)),
            "states": [{"at": [r[0], r[1]], "human": [r[2], r[3]], "model": [r[4], r[5]]}
                       for r in points.tolist()]}


_BANKS: dict = {}  # the loaded trial bank as the analysis reads it, by its SHA-256


def analysis_bank(ctx: StudyContext):
    """The study's trial bank as analysis.bank.Bank (every seed's answers), built once."""
    from analysis.bank import Bank

    if ctx.bank.sha256 not in _BANKS:
        _BANKS[ctx.bank.sha256] = Bank(ctx.bank.data.model_dump(mode="json"), ctx.bank.sha256)
    return _BANKS[ctx.bank.sha256]


def primary_verdicts(kept: pd.DataFrame, ctx: StudyContext) -> dict[str, str]:
    """Per world, the report's first-page sentence (analysis.verdicts.primary_sentence) for
    the pre-registered primary test on the rows kept so far; {} until rows ran the bank."""
    from analysis.crossed import primary_table
    from analysis.seeds import seed_results
    from analysis.stats import ALPHA, plain_records
    from analysis.verdicts import primary_sentence

    if kept.empty:
        return {}
    seeds = seed_results(kept, analysis_bank(ctx), "the loaded trial bank")
    if not seeds.ok:
        return {}
    table = primary_table(seeds.family_rows, ALPHA, ctx.config.exploratory_worlds,
                          ctx.config.smallest_effect_of_interest)
    return {row["world"]: primary_sentence(row["world"], row) for row in plain_records(table)}


def alignment(frame: pd.DataFrame, ctx: StudyContext, rule_set: str) -> dict:
    """Exclusions, the primary test's verdict per world in words, per-world error CIs of every
    predictor (with their colours and labels, one definition: app/core/contracts.py) and field
    panels under one rule set, on the study's predictions export `frame`."""
    from app.core.contracts import model_style

    names = every_predictor(ctx)
    out = {"rules": rule_set, "predictors": names, "style": model_style(names)}
    if frame.empty:
        return out | {"exclusions": {}, "verdicts": {}, "worlds": {}, "fields": {}}
    kept, counts = kept_rows(frame, ctx, rule_set)
    return out | {"exclusions": counts, "verdicts": primary_verdicts(kept, ctx),
                  "worlds": world_errors(kept, names), "fields": world_fields(kept, ctx)}


def dashboard(db: Session, ctx: StudyContext, rule_set: str = "kept",
              external_ids: bool = False) -> dict:
    """Everything the dashboard's live part shows, in one answer."""
    people = study_sessions(db, ctx.study_id)  # loaded once for both
    frame = predictions_frame(db, ctx.study_id, stored_predictors(ctx.config))
    return {"study_id": ctx.study_id,
            "progress": progress_counts(ctx, people) | usable_counts(frame, ctx),
            "time_and_pay": time_and_pay(ctx, people),
            "participants": participant_rows(db, ctx, people, external_ids),
            "versions": versions(db, ctx), "alignment": alignment(frame, ctx, rule_set),
            "completion_codes": codes_table(ctx.config)}


def usable_counts(frame: pd.DataFrame, ctx: StudyContext) -> dict:
    """The headline's count: the participants the analysis keeps under the study's own
    exclusion rules (whatever rule set the panels show), and per rule how many finished
    sessions it excludes."""
    from analysis.metrics import apply_exclusions

    if frame.empty:
        return {"usable": 0, "excluded_by_rule": {}}
    counts = apply_exclusions(frame, ctx.config.exclusions).counts()
    never_data = ("pilot", "replaced", "incomplete")  # not finished sessions of the study
    return {"usable": counts["participants_kept"],
            "excluded_by_rule": {key.removeprefix("excluded_"): n for key, n in counts.items()
                                 if key.startswith("excluded_") and n
                                 and key.removeprefix("excluded_") not in never_data}}
