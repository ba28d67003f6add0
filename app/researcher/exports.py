"""The researcher's four exports as typed DataFrames and spreadsheet-safe CSV (read-only).

- `predictions`: the analysis table, one row per (participant, trial, start state, step),
  with each plug-in predictor's columns after the contract's;
- `survey`: one row per (participant, answered question);
- `events`: telemetry events and each trial's undo/reset presses, one long table;
- `participants`: the payment and approval sheet, one row per session, with whether the
  analysis excludes it and why.

The analysis exports carry the session's random `public_id` as `participant_id`, never
the platform's id; only `participants` links the two. Every row carries the config and
bank hashes of its own session, so a study changed mid-way shows it per row, and the export's
`export_version`. Columns and dtypes: analysis/load.py (predictions) and analysis/exports.py
(the others).
"""

import io
import json
from collections import defaultdict
from datetime import datetime
from pathlib import Path

import pandas as pd
from sqlalchemy import func, select
from sqlmodel import Session

from analysis.codebook import StudyTerms, data_package
from analysis.exports import typed
from analysis.load import expand_plugins, normalise, stored_columns
from app.core.contracts import (
    DEVICE,
    EVENTS,
    EXPORT_COLUMNS,
    EXPORT_VERSION,
    PARTICIPANTS,
    PROLIFIC_UNCONFIRMED,
    SURVEY,
    WHAT,
    ExclusionRules,
)
from app.core.csvsafe import write_csv
from app.core.files import write_json
from app.server.queries import (
    SERVER_EVENTS,
    Cutoffs,
    Event,
    Participant,
    PredictionRow,
    Submission,
    TrialResponse,
    as_utc,
    exclusion_reasons,
    session_status,
    status_cutoffs,
    trial_speeds,
    trial_steps,
)
from app.study.config import StudyConfig, stored_predictors


def export_table(db: Session, config: StudyConfig, study_id: str, what: str) -> pd.DataFrame:
    """One of the exports (`WHAT`) of a study as a typed DataFrame."""
    if what == "predictions":
        return predictions_frame(db, study_id, stored_predictors(config))
    if what == "survey":
        return survey_frame(db, config, study_id)
    if what == "events":
        return events_frame(db, study_id)
    if what == "participants":
        return participants_frame(db, config, study_id)
    raise ValueError(f"what: unknown export {what!r}; choose one of {', '.join(WHAT)}")


def export_csv(db: Session, config: StudyConfig, study_id: str, what: str) -> str:
    """An export as CSV text; text cells a spreadsheet would run as a formula start with a
    quote (app/core/csvsafe.py), which analysis.exports.read_export removes."""
    return csv_text(export_table(db, config, study_id, what))


def csv_text(frame: pd.DataFrame) -> str:
    """An export's frame as the CSV text every export is written as."""
    buffer = io.StringIO()
    write_csv(frame, buffer)
    return buffer.getvalue()


def export_filename(study_id: str, what: str) -> str:
    """The file name a downloaded export is saved as (and its data package names)."""
    return f"{study_id}_{what}.csv"


def package_path(csv_path: Path) -> Path:
    """Where an export's data package goes: FILE.csv -> FILE.datapackage.json beside it."""
    return csv_path.with_name(csv_path.name.removesuffix(".csv") + ".datapackage.json")


def write_export_package(frame: pd.DataFrame, config: StudyConfig, study_id: str, what: str,
                         csv_path: Path) -> Path:
    """Write the data package of the export CSV at `csv_path` (holding `frame`) beside it."""
    target = package_path(csv_path)
    write_json(target, export_package(frame, config, study_id, what, csv_path.read_bytes(),
                                      csv_path.name))
    return target


def export_package(frame: pd.DataFrame, config: StudyConfig, study_id: str, what: str,
                   csv: bytes, path: str) -> dict:
    """The Frictionless Data Package (analysis/codebook.py) of an export: `frame` as written
    to `csv`, saved as `path` beside the package."""
    terms = StudyTerms(worlds=tuple(config.worlds),
                       questions=tuple(q.key for q in config.survey))
    return data_package(what, list(frame.columns), csv, path, len(frame), study_id,
                        row_hashes(frame), terms)


def row_hashes(frame: pd.DataFrame) -> dict[str, list[str]]:
    """The config, bank and model hashes an export's rows carry, each distinct value once
    (a predictions export's models_sha256 as the other exports give it, per session)."""
    hashes = {key: sorted(set(frame[key])) for key in ("config_sha256", "bank_sha256")}
    if "models_sha256" in frame:
        return hashes | {"models_sha256": sorted(set(frame["models_sha256"]))}
    models: dict[str, dict] = defaultdict(dict)
    cells = frame[["participant_id", "world", "ours_sha256", "vae_sha256"]].drop_duplicates()
    for session, world, ours, vae in cells.itertuples(index=False):
        models[session][world] = {"ours": ours, "vae": vae}
    return hashes | {"models_sha256": sorted({_models_json(m) for m in models.values()})}


def _models_json(models: dict) -> str:
    return json.dumps(models, sort_keys=True, separators=(",", ":"))


# ---------------------------------------------------------------- predictions

def predictions_frame(db: Session, study_id: str, plugins: list[str] = ()) -> pd.DataFrame:
    """One row per (participant, trial, start state, step), columns as in API.md, then the
    four columns of each plug-in predictor in `plugins` (the study config's order)."""
    pred, trial, part = PredictionRow.__table__, TrialResponse.__table__, Participant.__table__
    query = (
        select(part.c.study_id, part.c.public_id.label("participant_id"), part.c.recruitment,
               part.c.completed, part.c.outcome, part.c.prolific_check,
               part.c.replaced_at.is_not(None).label("replaced"),
               (part.c.attention_failed == 0).label("attention_passed"), trial.c.world,
               trial.c.world_position, trial.c.trial_index, trial.c.is_practice,
               trial.c.attention_check, trial.c.arm, trial.c.clip_sha256,
               trial.c.duration_ms.label("trial_duration_ms"), trial.c.replays,
               trial.c.received_at.label("submitted_at"), part.c.config_sha256,
               part.c.bank_sha256, *stored_columns(pred, ("participant_id",)), pred.c.plugins)
        .select_from(pred.join(trial, trial.c.submission_id == pred.c.submission_id)
                     .join(part, part.c.id == pred.c.participant_id))
        .where(part.c.study_id == study_id)
        .order_by(pred.c.participant_id, trial.c.id, pred.c.start_index, pred.c.step))
    rows = [dict(r) for r in db.execute(query).mappings()]
    frame = pd.DataFrame(rows, columns=[*EXPORT_COLUMNS, "plugins"])
    frame["submitted_at"] = [as_utc(t).isoformat() for t in frame["submitted_at"]]
    frame["export_version"] = EXPORT_VERSION
    return normalise(expand_plugins(frame, list(plugins)))


# ---------------------------------------------------------------- the sessions

def _sessions(db: Session, study_id: str) -> list[Participant]:
    query = select(Participant).where(Participant.study_id == study_id).order_by(Participant.id)
    return list(db.execute(query).scalars().all())


def _models(db: Session, study_id: str) -> dict[int, str]:
    """Session id -> JSON of the model hashes its answers came from, per world."""
    pred, trial, part = PredictionRow.__table__, TrialResponse.__table__, Participant.__table__
    rows = db.execute(
        select(pred.c.participant_id, trial.c.world, pred.c.ours_sha256, pred.c.vae_sha256)
        .distinct()
        .select_from(pred.join(trial, trial.c.submission_id == pred.c.submission_id)
                     .join(part, part.c.id == pred.c.participant_id))
        .where(part.c.study_id == study_id))
    models: dict[int, dict] = defaultdict(dict)
    for session, world, ours, vae in rows:
        models[session][world] = {"ours": ours, "vae": vae}
    return {k: _models_json(v) for k, v in models.items()}


def _versions(sessions: list[Participant], models: dict[int, str]) -> dict[int, dict]:
    """Session id -> the export version, public id and study version columns of its rows."""
    return {p.id: {"export_version": EXPORT_VERSION, "study_id": p.study_id,
                   "participant_id": p.public_id,
                   "config_sha256": p.config_sha256, "bank_sha256": p.bank_sha256,
                   "models_sha256": models.get(p.id, "{}")} for p in sessions}


def _of_study(query, table, study_id: str):
    """`query` over `table`'s rows of the study's sessions."""
    return query.join(Participant, Participant.id == table.participant_id).where(
        Participant.study_id == study_id)


def _utc(moment: datetime | None) -> datetime | None:
    return None if moment is None else as_utc(moment)


# ---------------------------------------------------------------- survey

def survey_frame(db: Session, config: StudyConfig, study_id: str) -> pd.DataFrame:
    """One row per (participant, answered question), in the config's question order."""
    sessions = _sessions(db, study_id)
    versions = _versions(sessions, _models(db, study_id))
    kinds = {q.key: q.kind for q in config.survey}
    order = {key: i for i, key in enumerate(kinds)}
    found = db.execute(_of_study(select(Submission.participant_id, Submission.payload,
                                        Submission.received_at), Submission, study_id)
                       .where(Submission.kind == "survey").order_by(Submission.participant_id))
    rows = []
    for session, payload, received in found:
        answers = payload.get("answers", {})
        for key in sorted(answers, key=lambda k: order.get(k, len(order))):
            rows.append({**versions[session], "question": key, "kind": kinds.get(key, ""),
                         "answer": str(answers[key]), "answered_at": _utc(received)})
    return typed(pd.DataFrame(rows), SURVEY)


# ---------------------------------------------------------------- events

def events_frame(db: Session, study_id: str) -> pd.DataFrame:
    """Telemetry events and undo/reset presses of every session, by session and client time."""
    sessions = _sessions(db, study_id)
    versions = _versions(sessions, _models(db, study_id))
    bank_ids = {p.id: {step.ref: step.trial_id for _, step in trial_steps(p)} for p in sessions}
    rows = (_telemetry_rows(db, study_id, versions, bank_ids)
            + _history_rows(db, study_id, versions))
    frame = typed(pd.DataFrame(rows), EVENTS)
    return frame.sort_values(["participant_id", "t_client_ms"], kind="stable",
                             ignore_index=True)


def _telemetry_rows(db: Session, study_id: str, versions: dict[int, dict],
                    bank_ids: dict[int, dict[str, str]]) -> list[dict]:
    found = db.execute(_of_study(select(Event.participant_id, Event.kind, Event.t_client_ms,
                                        Event.data, Event.received_at), Event, study_id)
                       .order_by(Event.id))
    rows = []
    for session, kind, t_client_ms, data, received in found:
        ref = data.get("trial_id")  # the browser's opaque id of the trial on screen
        rows.append({**versions[session], "source": _source(kind), "kind": kind,
                     "t_client_ms": t_client_ms, "received_at": _utc(received),
                     "trial_id": bank_ids[session].get(ref, ref), "replays": data.get("replays"),
                     "start_index": data.get("start_index"), "clicks": data.get("clicks"),
                     "w": data.get("w"), "h": data.get("h")})
    return rows


def _source(kind: str) -> str:
    """`telemetry` for what the browser reports, `server` for what the server saw (tabs.py)."""
    return "server" if kind in SERVER_EVENTS else "telemetry"


def _history_rows(db: Session, study_id: str, versions: dict[int, dict]) -> list[dict]:
    found = db.execute(_of_study(select(TrialResponse.participant_id, TrialResponse.trial_id,
                                        TrialResponse.shown_at_ms, TrialResponse.history,
                                        TrialResponse.received_at), TrialResponse, study_id)
                       .order_by(TrialResponse.id))
    rows = []
    for session, trial_id, shown_at_ms, history, received in found:
        for press in history or []:
            rows.append({**versions[session], "source": "trial_history",
                         "kind": press["action"], "t_client_ms": shown_at_ms + press["t_ms"],
                         "t_trial_ms": press["t_ms"], "received_at": _utc(received),
                         "trial_id": trial_id, "start_index": press["start_index"]})
    return rows


# ---------------------------------------------------------------- participants

def participants_frame(db: Session, config: StudyConfig, study_id: str) -> pd.DataFrame:
    """The payment and approval sheet: one row per session (replaced and pilot ones too)."""
    sessions = _sessions(db, study_id)
    versions = _versions(sessions, _models(db, study_id))
    checks = checks_answered(db, study_id)
    cutoffs = status_cutoffs(config)
    speeds = trial_speeds(db, config.exclusions, Participant.study_id == study_id)
    rows = [_participant_row(p, versions[p.id], checks.get(p.id, 0), cutoffs)
            | _exclusion(config.exclusions, p, speeds.get(p.id, (0, 0))) for p in sessions]
    return typed(pd.DataFrame(rows), PARTICIPANTS)


def _exclusion(rules: ExclusionRules, p: Participant, speeds: tuple[int, int]) -> dict:
    """Whether the analysis leaves the session out, and why (the same rules, `;`-joined)."""
    reasons = exclusion_reasons(rules, p.attention_failed, *speeds)
    if rules.incomplete and not p.completed:
        reasons.append("incomplete")
    reasons += [why for why, applies in (
        ("pilot", p.pilot), ("replaced", p.replaced_at is not None),
        ("prolific_unknown", p.prolific_check in PROLIFIC_UNCONFIRMED)) if applies]
    return {"excluded": bool(reasons), "exclusion_reasons": ";".join(reasons)}


def checks_answered(db: Session, study_id: str) -> dict[int, int]:
    """Attention-check trials answered, per participant row id."""
    query = _of_study(select(TrialResponse.participant_id, func.count()), TrialResponse,
                      study_id)
    rows = db.execute(query.where(TrialResponse.attention_check.is_(True))
                      .group_by(TrialResponse.participant_id))
    return dict(rows.all())


def _participant_row(p: Participant, version: dict, checks: int, cutoffs: Cutoffs) -> dict:
    started, last_seen = as_utc(p.created_at), as_utc(p.updated_at)
    ended = _utc(p.ended_at)
    return {**version, "external_id": p.external_id, "recruitment": p.recruitment,
            "outcome": p.outcome, "completion_code": p.completion_code,
            "status": session_status(p, cutoffs), "started_at": started, "ended_at": ended,
            "duration_min": None if ended is None else (ended - started).total_seconds() / 60,
            "last_seen": last_seen, "world_order": p.world_order,
            "steps_done": p.position, "steps_total": len(p.plan), "attention_checks": checks,
            "attention_failed": p.attention_failed,
            "attention_verdict": attention_verdict(checks, p.attention_failed),
            "pilot": p.pilot, "replaced": p.replaced_at is not None,
            "prolific_check": p.prolific_check or "", "app_version": p.app_version,
            **device_columns(p.client)}


def device_columns(client: dict) -> dict:
    """The consented device (schemas.ClientInfo) as DEVICE columns; -1 and '' without one."""
    return {key: client.get(key, -1 if kind == "int" else "" if kind == "text" else False)
            for key, kind in DEVICE.items()}


def attention_verdict(checks: int, failed: int) -> str:
    """failed (any check failed: review before rejecting), passed, or none (no check yet)."""
    if failed:
        return "failed"
    return "passed" if checks else "none"
