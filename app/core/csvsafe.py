"""CSV a spreadsheet cannot run: text cells that would start a formula begin with a quote.

Excel, LibreOffice and Google Sheets read a cell starting with `=`, `+`, `-`, `@`, tab or
carriage return as a formula, even inside CSV quotes, and a participant controls some
cells (a Prolific id, survey text). OWASP's advice, followed here: prefix such a text cell
with a single quote, which spreadsheets take as "this is text". Only text is touched:
numeric columns keep their values and type (-1.5 stays -1.5).

A text that already starts with a quote gets one more, so `restore_text` gives back
exactly what was written and the analysis reads the CSV as it reads the database.
"""

from pathlib import Path
from typing import IO

import pandas as pd

FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
QUOTE = "'"
_QUOTED_STARTS = (*FORMULA_STARTS, QUOTE)


def safe_cell(value: object) -> object:
    """`value`, with a leading quote if it is text a spreadsheet could run (or quoted)."""
    if isinstance(value, str) and value.startswith(_QUOTED_STARTS):
        return QUOTE + value
    return value


def restore_cell(value: object) -> object:
    """The text `safe_cell` was given (anything else unchanged)."""
    if isinstance(value, str) and value.startswith(QUOTE) and value[1:].startswith(_QUOTED_STARTS):
        return value[1:]
    return value


def spreadsheet_safe(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of `frame` whose text cells are safe (`safe_cell`); other columns as they are."""
    return frame.assign(**{c: frame[c].map(safe_cell) for c in frame if _is_text(frame[c])})


def restore_text(frame: pd.DataFrame, columns: list[str] | tuple[str, ...]) -> pd.DataFrame:
    """`frame` with the text of `columns` as it was before `spreadsheet_safe`."""
    return frame.assign(**{c: frame[c].map(restore_cell) for c in columns if c in frame})


def write_csv(frame: pd.DataFrame, target: Path | IO[str], **to_csv_args) -> None:
    """`frame.to_csv(target, index=False, ...)` with spreadsheet-safe text cells."""
    spreadsheet_safe(frame).to_csv(target, index=False, **to_csv_args)


def _is_text(column: pd.Series) -> bool:
    return pd.api.types.is_object_dtype(column) or pd.api.types.is_string_dtype(column)
