"""Read the study's predictions, from the exported CSV or straight from the database.

Both readers return the same tidy DataFrame: one row per (participant, trial, start state,
step), the columns of the export contract (app/http/API.md) with fixed dtypes, then each
plug-in predictor's four columns (`<name>_vx`, `_vy`, `_code`, `_sha256`), sorted by
participant, trial, start state and step. An older export reads under the current column
names, its own `export_version` kept. `participant_id` is the session's random
public id: the predictions carry no platform id.
"""

import hashlib
import json
from datetime import UTC
from pathlib import Path

import numpy as np
import pandas as pd

from app.core.contracts import (
    ADDED_COLUMNS,
    COARSE_OBSERVERS,
    EXPORT_COLUMNS,
    EXPORT_VERSION,
    PLUGIN_FIELDS,
    RENAMED_COLUMNS,
    SORT_KEYS,
    STORED_NAMES,
    column_kinds,
    plugin_columns,
)
from app.core.csvsafe import restore_text


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


def _cast(values: pd.Series, kind: str) -> pd.Series:
    if kind == "text":
        return values.fillna("").astype(str) if values.hasnans else values.astype(str)
    if kind == "bool":
        return _as_bool(values)
    if kind == "int":
        return pd.to_numeric(values, errors="coerce").fillna(-1).astype(np.int64)
    return pd.to_numeric(values, errors="coerce").astype(np.float64)


def normalise(frame: pd.DataFrame) -> pd.DataFrame:
    """Cast the export columns (and plug-in predictors' columns) to fixed dtypes and sort;
    other columns are dropped, an export without export_version (version 1) has its renamed
    columns (RENAMED_COLUMNS) read under their current names, and columns newer than the
    export (ADDED_COLUMNS) get the value older rows read as."""
    if "export_version" not in frame.columns:
        frame = frame.rename(columns=RENAMED_COLUMNS)
    frame = frame.assign(**{c: v for c, v in ADDED_COLUMNS.items() if c not in frame.columns})
    missing = [c for c in EXPORT_COLUMNS if c not in frame.columns]
    if missing:
        raise DataError(f"missing columns: {', '.join(missing)}")
    out = pd.DataFrame(index=frame.index)
    for col, kind in column_kinds(frame.columns).items():
        out[col] = _cast(frame[col], kind)
    _check_version(out["export_version"])
    return out.sort_values(SORT_KEYS, kind="stable").reset_index(drop=True)


def _check_version(versions: pd.Series) -> None:
    """Refuse rows of an export newer than this code reads (its columns may mean other things)."""
    newest = int(versions.max()) if len(versions) else EXPORT_VERSION
    if newest > EXPORT_VERSION:
        raise DataError(f"export_version: {newest} is newer than this analysis reads "
                        f"({EXPORT_VERSION}); update tomstudy")


def stored_columns(table, skip: tuple[str, ...] = ()) -> list:
    """The export contract's columns `table` (a database table) holds, each labelled with its
    export name (the database keeps the names before export_version 2: STORED_NAMES)."""
    return [table.c[STORED_NAMES.get(c, c)].label(c) for c in EXPORT_COLUMNS
            if STORED_NAMES.get(c, c) in table.c and c not in skip]


def expand_plugins(frame: pd.DataFrame, names: list[str] | None = None) -> pd.DataFrame:
    """The server's `plugins` JSON column as each plug-in predictor's export columns (`names`,
    or every one the rows hold); a row without a plug-in's answer gets empty cells."""
    cells = frame.pop("plugins") if "plugins" in frame.columns else [{}] * len(frame)
    cells = [json.loads(c) if isinstance(c, str) else (c or {}) for c in cells]
    if names is None:  # the coarse observers first, as the server's export orders them
        found = list(dict.fromkeys(name for cell in cells for name in cell))
        names = sorted(found, key=lambda n: (COARSE_OBSERVERS + (n,)).index(n))
    for name in names:
        for field, column in zip(PLUGIN_FIELDS, plugin_columns(name), strict=True):
            frame[column] = [cell.get(name, {}).get(field) for cell in cells]
    return frame


def load_csv(path: Path) -> pd.DataFrame:
    """The export CSV as a normalised DataFrame (typed while parsing, which is fast), its
    text as the server stored it (the quote that kept it from spreadsheets removed)."""
    try:
        kinds = column_kinds(_header(path))
        texts = [c for c, kind in kinds.items() if kind == "text"]
        numbers = [c for c, kind in kinds.items() if kind in ("int", "float")]
        dtypes = {c: str for c in texts} | {c: np.float64 for c in numbers}
        raw = pd.read_csv(path, dtype=dtypes, keep_default_na=False,
                          na_values={c: [""] for c in numbers},
                          true_values=["True", "true"], false_values=["False", "false"])
    except ValueError as err:
        raise DataError(f"{path}: {err}") from err
    return normalise(restore_text(raw, texts))  # as the database holds them


def _header(source) -> list[str]:
    """A CSV's column names (an open file is left where it was)."""
    if not hasattr(source, "seek"):
        return list(pd.read_csv(source, nrows=0).columns)
    where = source.tell()
    columns = list(pd.read_csv(source, nrows=0).columns)
    source.seek(where)
    return columns


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
                *[part.c[c] for c in ("prolific_check",) if c in part.c],  # since 0008
                (part.c.attention_failed == 0).label("attention_passed"),
                trial.c.world, trial.c.world_position, trial.c.trial_id, trial.c.trial_index,
                trial.c.is_practice, trial.c.attention_check, trial.c.clip_sha256,
                *[trial.c[c] for c in ADDED_COLUMNS if c in trial.c],  # older schemas lack them
                *stored_columns(pred, ("participant_id", "trial_id", "submission_id")),
                trial.c.duration_ms.label("trial_duration_ms"), trial.c.replays,
                pred.c.submission_id, trial.c.received_at.label("submitted_at"),
                *[pred.c[c] for c in ("plugins",) if c in pred.c])  # older schemas lack it
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
    frame["export_version"] = EXPORT_VERSION  # the rows as the export writes them now
    return normalise(expand_plugins(frame))


def _iso_time(value) -> str:
    """Timestamps as ISO-8601 text, as the CSV export writes them (naive = UTC, from SQLite)."""
    if value is None or value == "":
        return ""
    if not hasattr(value, "isoformat"):
        return str(value)
    if value.tzinfo is None:
        value = value.replace(tzinfo=UTC)
    return value.isoformat()
