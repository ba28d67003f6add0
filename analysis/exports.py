"""One reader for every researcher export that gives each column its contract's dtype.

`predictions` is the analysis table (analysis/load.py). The other three are
`survey`, `events` and `participants`; each column has one of five types:
text (pandas `str`, "" when absent), int (int64, -1 when not applicable), float
(float64, NaN when absent), bool, and time (datetime64[us, UTC], NaT when absent;
ISO 8601 in the CSV). Text cells are spreadsheet-safe in the CSV (app/core/csvsafe.py); the reader
gives back the text as stored.
"""

from pathlib import Path
from typing import IO

import numpy as np
import pandas as pd

from analysis.load import load_csv
from app.core.contracts import ADDED_COLUMNS, SCHEMAS
from app.core.csvsafe import restore_text


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
    """An export CSV as written, with the dtypes of its contract (an export older than a
    column, such as export_version, reads with the value of ADDED_COLUMNS)."""
    if what == "predictions":
        return load_csv(source)
    schema = SCHEMAS[what]
    text = [c for c, k in schema.items() if k == "text"]
    numbers = [c for c, k in schema.items() if k in ("int", "float")]
    raw = pd.read_csv(source, dtype={c: str for c in text} | {c: np.float64 for c in numbers},
                      keep_default_na=False, na_values={c: [""] for c in numbers},
                      true_values=["True"], false_values=["False"])
    raw = raw.assign(**{c: v for c, v in ADDED_COLUMNS.items() if c in schema and c not in raw})
    return typed(restore_text(raw, text), schema)
