"""Where a study stands, for researchers: progress counts, the exclusion rules in force and the
live alignment summary (the CSV exports are in exports.py)."""

from collections import Counter

import pandas as pd
from sqlalchemy import select
from sqlmodel import Session

from app.researcher.exports import predictions_frame
from app.server.queries import (
    Participant,
    StudyContext,
    codes_table,
    preview_path,
    session_status,
    status_cutoffs,
)
from app.study.config import stored_predictors


def progress(db: Session, ctx: StudyContext) -> dict:
    """progress_counts of the study's stored sessions."""
    return progress_counts(ctx, study_sessions(db, ctx.study_id))


def study_sessions(db: Session, study_id: str) -> list[Participant]:
    """Every session of the study, pilots and replaced ones included, in order of start."""
    return list(db.execute(select(Participant).where(Participant.study_id == study_id)
                           .order_by(Participant.created_at, Participant.id)).scalars().all())


def progress_counts(ctx: StudyContext, everyone: list[Participant]) -> dict:
    """Session counts: started, completed, in progress, ended early (declined, screened
    out), stale, by outcome and per world order.

    A session is in progress, and in its world order's counts, only from consent on (as it
    counts for the study, places.py); before, it is `awaiting_consent`. Pilot (preview)
    sessions and sessions replaced by a new attempt are counted apart and never in the
    study's progress.
    """
    cutoffs = status_cutoffs(ctx.config)
    people = [p for p in everyone if not p.pilot and p.replaced_at is None]
    status = {p.id: session_status(p, cutoffs) for p in people}
    completed = [p for p in people if p.completed]
    orders: dict[str, dict[str, int]] = {}
    for p in people:
        entry = orders.setdefault(p.world_order, {"completed": 0, "in_progress": 0})
        if p.completed:
            entry["completed"] += 1
        elif status[p.id] == "in_progress":
            entry["in_progress"] += 1
    counts = Counter(status.values())
    return {"target_sample_size": ctx.config.target_sample_size, "started": len(people),
            "completed": len(completed), "in_progress": counts["in_progress"],
            "awaiting_consent": counts["awaiting_consent"],
            "ended_early": counts["ended"] - len(completed), "stale": counts["stale"],
            "outcomes": dict(Counter(p.outcome for p in people if p.outcome)),
            "failed_attention_check": sum(p.attention_failed > 0 for p in completed),
            "pilot_sessions": sum(p.pilot for p in everyone),
            "replaced_sessions": sum(p.replaced_at is not None for p in everyone),
            "world_orders": orders}


def exclusion_rules(ctx: StudyContext, rule_set: str):
    """The study's exclusion rules (`kept`), or (`live`) the same with `incomplete` waived."""
    rules = ctx.config.exclusions
    return rules if rule_set == "kept" else rules.model_copy(update={"incomplete": False})


def every_predictor(ctx: StudyContext) -> list[str]:
    """Every predictor of the study in the order researchers see them (Ours, the VAE, constant
    velocity, the coarse observers, each plug-in of the config), then the policy (the precise
    observer) as the reference."""
    from analysis.predictors import BUILT_IN, REFERENCE

    return [*BUILT_IN, *stored_predictors(ctx.config), REFERENCE]


def alignment_summary(frame: pd.DataFrame, ctx: StudyContext) -> dict:
    """Running mean alignment error per world and predictor (every_predictor), with the
    analysis' exclusion rules.

    `kept` applies every rule (so only completed sessions); `live` waives the
    `incomplete` rule to show sessions still running. `frame` is predictions_frame's
    (already normalised).
    """
    from analysis.metrics import apply_exclusions, participant_means

    if frame.empty:
        return {"kept": {}, "live": {}, "exclusions": {}}
    out = {}
    names = tuple(every_predictor(ctx))
    for name in ("kept", "live"):
        result = apply_exclusions(frame, exclusion_rules(ctx, name))
        out[name] = (_world_means(participant_means(result.kept, names), names)
                     if len(result.kept) else {})
        if name == "kept":
            out["exclusions"] = result.counts()
    return out


def _world_means(means: pd.DataFrame, names: tuple[str, ...]) -> dict:
    summary = {}
    for world, group in means.groupby("world", sort=True):
        summary[world] = {"participants": int(len(group)), **{
            model: round(float(group[f"err_{model}"].mean()), 4)
            for model in names}}
    return summary


def summary(db: Session, ctx: StudyContext) -> dict:
    """The dashboard's JSON: progress, exclusions and running alignment error."""
    frame = predictions_frame(db, ctx.study_id, stored_predictors(ctx.config))
    return {"study_id": ctx.study_id, "title": ctx.config.title,
            "preview_link": preview_path(ctx.study_id, ctx.preview_key),
            "progress": progress(db, ctx), "alignment_error": alignment_summary(frame, ctx),
            "rows": int(len(frame)), "completion_codes": codes_table(ctx.config)}
