"""Column contracts of the researcher's exports, and one reader that gives each its dtypes.

`predictions` is the analysis table (analysis/load.py). The other three are
`survey`, `events` and `participants`; each column has one of five types:
text (pandas `str`, "" when absent), int (int64, -1 when not applicable), float
(float64, NaN when absent), bool, and time (datetime64[us, UTC], NaT when absent;
ISO 8601 in the CSV). Text cells are spreadsheet-safe in the CSV (analysis/csvsafe.py); the reader
gives back the text as stored.
"""

from pathlib import Path
from typing import IO

import numpy as np
import pandas as pd

from analysis.csvsafe import restore_text
from analysis.load import load_csv

# Every export except predictions (whose rows carry each model's hash already) names
# the models a session's answers came from as JSON: {"<world>": {"ours": sha, "vae": sha}}.
STUDY_VERSION = {"config_sha256": "text", "bank_sha256": "text", "models_sha256": "text"}

SURVEY = {
    "study_id": "text", "participant_id": "text", "question": "text", "kind": "text",
    "answer": "text", "answered_at": "time", **STUDY_VERSION,
}
EVENTS = {
    "study_id": "text", "participant_id": "text", "source": "text", "kind": "text",
    "t_client_ms": "float", "t_trial_ms": "float", "received_at": "time",
    "trial_id": "text", "start_index": "int", "replays": "int", "w": "int", "h": "int",
    **STUDY_VERSION,
}
PARTICIPANTS = {
    "study_id": "text", "external_id": "text", "recruitment": "text",
    "participant_id": "text", "outcome": "text", "completion_code": "text",
    "status": "text", "started_at": "time", "ended_at": "time", "duration_min": "float",
    "last_seen": "time", "world_order": "text", "steps_done": "int", "steps_total": "int",
    "attention_checks": "int", "attention_failed": "int", "attention_verdict": "text",
    "pilot": "bool", "replaced": "bool", "app_version": "text", **STUDY_VERSION,
}
SCHEMAS = {"survey": SURVEY, "events": EVENTS, "participants": PARTICIPANTS}
WHAT = ("predictions", *SCHEMAS)


def typed(frame: pd.DataFrame, schema: dict[str, str]) -> pd.DataFrame:
    """`frame`'s schema columns, in order, cast to the schema's dtypes."""
    out = pd.DataFrame(index=frame.index)
    for col, kind in schema.items():
        values = frame[col] if col in frame else pd.Series([None] * len(frame), index=frame.index)
        out[col] = _cast(values, kind)
    return out.reset_index(drop=True)


def _cast(values: pd.Series, kind: str) -> pd.Series:
    if kind == "text":
        return values.astype(object).where(values.notna(), "").astype(str)
    if kind == "int":
        return pd.to_numeric(values, errors="coerce").fillna(-1).astype(np.int64)
    if kind == "float":
        return pd.to_numeric(values, errors="coerce").astype(np.float64)
    if kind == "bool":
        return values.astype(bool)
    return pd.to_datetime(values, utc=True, format="ISO8601").astype("datetime64[us, UTC]")


def read_export(source: Path | IO[str], what: str) -> pd.DataFrame:
    """An export CSV as written, with the dtypes of its contract."""
    if what == "predictions":
        return load_csv(source)
    schema = SCHEMAS[what]
    text = [c for c, k in schema.items() if k == "text"]
    numbers = [c for c, k in schema.items() if k in ("int", "float")]
    raw = pd.read_csv(source, dtype={c: str for c in text} | {c: np.float64 for c in numbers},
                      keep_default_na=False, na_values={c: [""] for c in numbers},
                      true_values=["True"], false_values=["False"])
    return typed(restore_text(raw, text), schema)
