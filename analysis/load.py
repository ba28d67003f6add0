"""Read the study's predictions, from the exported CSV or straight from the database.

Both readers return the same tidy DataFrame: one row per (participant, trial, start state,
step), the columns of the export contract (app/server/API.md) with fixed dtypes, sorted
by participant, trial, start state and step. `participant_id` is the session's random
public id: the predictions carry no platform id.
"""

import hashlib
from datetime import UTC
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.contracts import (
    ADDED_COLUMNS,
    BOOL_COLUMNS,
    EXPORT_COLUMNS,
    FLOAT_COLUMNS,
    INT_COLUMNS,
    SORT_KEYS,
    STRING_COLUMNS,
)
from analysis.csvsafe import restore_text


class DataError(ValueError):
    """The predictions table is missing columns or holds values of the wrong type."""


def _as_bool(values: pd.Series) -> pd.Series:
    if pd.api.types.is_bool_dtype(values) and not values.isna().any():
        return values.astype(bool)
    text = values.astype("string").str.strip().str.lower()
    mapped = text.map({"true": True, "1": True, "t": True, "false": False, "0": False,
                       "f": False, "1.0": True, "0.0": False})
    if mapped.isna().any():
        bad = values[mapped.isna()].iloc[0]
        raise DataError(f"{values.name}: not a boolean: {bad!r}")
    return mapped.astype(bool)


def normalise(frame: pd.DataFrame) -> pd.DataFrame:
    """Cast the export columns to fixed dtypes and sort; extra columns are dropped, and
    columns newer than the export (ADDED_COLUMNS) get the value older rows read as."""
    frame = frame.assign(**{c: v for c, v in ADDED_COLUMNS.items() if c not in frame.columns})
    missing = [c for c in EXPORT_COLUMNS if c not in frame.columns]
    if missing:
        raise DataError(f"missing columns: {', '.join(missing)}")
    out = pd.DataFrame(index=frame.index)
    for col in EXPORT_COLUMNS:
        values = frame[col]
        if col in STRING_COLUMNS:
            out[col] = values.fillna("").astype(str) if values.hasnans else values.astype(str)
        elif col in BOOL_COLUMNS:
            out[col] = _as_bool(values)
        elif col in INT_COLUMNS:
            numbers = pd.to_numeric(values, errors="coerce")
            out[col] = numbers.fillna(-1).astype(np.int64)
        else:
            out[col] = pd.to_numeric(values, errors="coerce").astype(np.float64)
    return out.sort_values(SORT_KEYS, kind="stable").reset_index(drop=True)


def load_csv(path: Path) -> pd.DataFrame:
    """The export CSV as a normalised DataFrame (typed while parsing, which is fast), its
    text as the server stored it (the quote that kept it from spreadsheets removed)."""
    dtypes = {c: str for c in STRING_COLUMNS}
    dtypes |= {c: np.float64 for c in (*FLOAT_COLUMNS, *INT_COLUMNS)}
    try:
        raw = pd.read_csv(path, dtype=dtypes, keep_default_na=False,
                          na_values={c: [""] for c in (*FLOAT_COLUMNS, *INT_COLUMNS)},
                          true_values=["True", "true"], false_values=["False", "false"])
    except ValueError as err:
        raise DataError(f"{path}: {err}") from err
    return normalise(restore_text(raw, STRING_COLUMNS))  # as the database holds them


def data_hash(frame: pd.DataFrame) -> str:
    """SHA-256 of the normalised rows, independent of where they were read from."""
    digest = hashlib.sha256()
    digest.update(",".join(frame.columns).encode())
    digest.update(pd.util.hash_pandas_object(frame, index=False).to_numpy().tobytes())
    return digest.hexdigest()


def load_database(url: str, study_id: str) -> pd.DataFrame:
    """The same rows read straight from the server's database (read-only, SQLAlchemy Core).

    Joins the server's tables `predictionrow` (one row per start state and step),
    `trialresponse` (the answered trial) and `participant`, as the CSV export does.
    """
    import sqlalchemy as sa

    if url.startswith(("postgresql://", "postgres://")):  # psycopg 3, as the server uses
        url = "postgresql+psycopg://" + url.split("://", 1)[1]
    engine = sa.create_engine(url)
    try:
        meta = sa.MetaData()
        meta.reflect(engine, only=["participant", "trialresponse", "predictionrow"])
        part, trial, pred = (meta.tables[n] for n in ("participant", "trialresponse",
                                                       "predictionrow"))
        query = (
            sa.select(
                part.c.study_id, part.c.public_id.label("participant_id"), part.c.recruitment,
                part.c.completed, part.c.outcome, part.c.config_sha256, part.c.bank_sha256,
                part.c.replaced_at.is_not(None).label("replaced"),
                (part.c.attention_failed == 0).label("attention_passed"),
                trial.c.world, trial.c.world_position, trial.c.trial_id, trial.c.trial_index,
                trial.c.is_practice, trial.c.attention_check, trial.c.clip_sha256,
                *[trial.c[c] for c in ADDED_COLUMNS if c in trial.c],  # older schemas lack them
                *[pred.c[c] for c in EXPORT_COLUMNS if c in pred.c and c not in
                  ("participant_id", "trial_id", "submission_id")],
                trial.c.duration_ms.label("trial_duration_ms"), trial.c.replays,
                pred.c.submission_id, trial.c.received_at.label("submitted_at"))
            .select_from(pred.join(trial, trial.c.submission_id == pred.c.submission_id)
                         .join(part, part.c.id == pred.c.participant_id))
            .where(part.c.study_id == study_id))
        with engine.connect() as conn:
            frame = pd.DataFrame(conn.execute(query).mappings().all())
    finally:
        engine.dispose()
    if frame.empty:
        frame = pd.DataFrame(columns=list(EXPORT_COLUMNS))
    frame["submitted_at"] = frame["submitted_at"].map(_iso_time)
    return normalise(frame)


def _iso_time(value) -> str:
    """Timestamps as ISO-8601 text, as the CSV export writes them (naive = UTC, from SQLite)."""
    if value is None or value == "":
        return ""
    if not hasattr(value, "isoformat"):
        return str(value)
    if value.tzinfo is None:
        value = value.replace(tzinfo=UTC)
    return value.isoformat()
