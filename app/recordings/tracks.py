"""Reading INTERACTION track files: layout discovery, validation, tracks per recording.

Two layouts of the public devkit documentation are read (10 Hz, 100 ms between frames):
- v1.0: <DIR>/recorded_trackfiles/<scenario>/vehicle_tracks_NNN.csv (+ optional
  pedestrian_tracks_NNN.csv), one continuous recording per file;
- v1.2: <DIR>/train/<scenario>_train.csv and <DIR>/val/<scenario>_val.csv with a leading
  `case_id` column; each case is a separate 4 s recording.

Every format problem raises `TrackFileError` whose message names file, line and column.
Cutting tracks into robot/human pairs is pairs.py's job.
"""

import csv
import math
from array import array
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

FRAME_MS = 100
VEHICLE_COLUMNS = ("track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy",
                   "psi_rad", "length", "width")
CASE_COLUMNS = ("case_id", *VEHICLE_COLUMNS)
PEDESTRIAN_COLUMNS = VEHICLE_COLUMNS[:8]
OPTIONAL_TRAILING = ("interesting_agent", "track_to_predict")
CAR_TYPES = frozenset({"car"})
NON_VEHICLE_TYPES = frozenset({"pedestrian/bicycle", "pedestrian", "bicycle"})
SPLITS = ("train", "val")


class TrackFileError(ValueError):
    """A track file does not follow the documented format; the message names file and line."""


class PartialDownload(TrackFileError):
    """The devkit's validation list names recordings that are not in the copy."""


@dataclass
class Track:
    """One agent in one recording: frames [T] on the recording's time grid, states [T, ...]."""

    track_id: int
    agent_type: str
    frames: np.ndarray
    xy: np.ndarray
    v: np.ndarray
    psi: np.ndarray
    length_m: float
    width_m: float
    name: str = ""  # the agent's id in a lab's log (csv_logs); empty for INTERACTION tracks

    @property
    def is_car(self) -> bool:
        """True for the agent types that can be robot or human."""
        return self.agent_type in CAR_TYPES


@dataclass
class Recording:
    """The tracks of one v1.0 file or one v1.2 case (frames share one grid)."""

    name: str
    source: Path
    tracks: list[Track]

    def counts(self) -> dict[str, int]:
        """Number of tracks per agent type."""
        out: dict[str, int] = {}
        for track in self.tracks:
            out[track.agent_type] = out.get(track.agent_type, 0) + 1
        return out


# ---------------------------------------------------------------- layout discovery


def detect_layout(data_dir: Path, scenario: str) -> str:
    """'v1.2' if train/<scenario>_train.csv exists, 'v1.0' if recorded_trackfiles/<scenario>/."""
    data_dir = Path(data_dir)
    if (data_dir / "train" / f"{scenario}_train.csv").is_file():
        return "v1.2"
    if (data_dir / "recorded_trackfiles" / scenario).is_dir():
        return "v1.0"
    raise TrackFileError(
        f"{data_dir}: no tracks for scenario {scenario!r}: looked for "
        f"{data_dir / 'train' / f'{scenario}_train.csv'} (v1.2) and "
        f"{data_dir / 'recorded_trackfiles' / scenario}/vehicle_tracks_NNN.csv (v1.0)")


def split_files(data_dir: Path, scenario: str, layout: str) -> dict[str, list[Path]]:
    """The track files of each split ('train', 'val'); v1.0 lists every file under both."""
    data_dir = Path(data_dir)
    if layout == "v1.2":
        files = {s: [data_dir / s / f"{scenario}_{s}.csv"] for s in SPLITS}
        if not files["val"][0].is_file():
            raise TrackFileError(f"{files['val'][0]}: validation file not found")
        return files
    folder = data_dir / "recorded_trackfiles" / scenario
    found = sorted(folder.glob("vehicle_tracks_*.csv")) + sorted(
        folder.glob("pedestrian_tracks_*.csv"))
    if not any(p.name.startswith("vehicle_tracks_") for p in found):
        raise TrackFileError(f"{folder}: no vehicle_tracks_NNN.csv files")
    return {s: found for s in SPLITS}


def load_recordings(files: list[Path]) -> list[Recording]:
    """Read and validate every file; v1.0 pedestrian files join their vehicle file's recording."""
    by_name: dict[str, Recording] = {}
    for path in files:
        for rec in read_track_file(path):
            key = rec.name.replace("pedestrian_tracks_", "vehicle_tracks_")
            if key in by_name:
                by_name[key].tracks.extend(rec.tracks)
            else:
                rec.name = key
                by_name[key] = rec
    return list(by_name.values())


# ---------------------------------------------------------------- one file


def read_track_file(path: Path) -> list[Recording]:
    """Validate and read one track file (any layout) into recordings."""
    path = Path(path)
    with csv_reader(path) as reader:
        header = next(reader, None)
        if header is None or not any(cell.strip() for cell in header):
            raise TrackFileError(f"{path}:1: empty file: expected a header line "
                                 f"({','.join(CASE_COLUMNS)} or {','.join(VEHICLE_COLUMNS)})")
        columns = _check_header(path, [c.strip() for c in header])
        rows = _plain_rows(path, columns)
        if rows is None:  # a row the vectorised reader cannot vouch for: this one names it
            rows = _parse_rows(path, reader, columns)
    if not rows:
        raise TrackFileError(f"{path}:2: no data rows after the header")
    return _group_tracks(path, rows, has_case="case_id" in columns)


@contextmanager
def csv_reader(path: Path, encoding: str = "utf-8") -> Iterator:
    """A csv.reader over the file's lines, with a byte progress bar while it is read."""
    with open(path, newline="", encoding=encoding) as fh, \
            tqdm(total=path.stat().st_size, unit="B", unit_scale=True, leave=False,
                 desc=f"read {path.name}") as bar:
        yield csv.reader(_counted_lines(fh, bar))


def _counted_lines(fh, bar, every: int = 20000):
    """The file's lines, advancing a byte progress bar every `every` lines."""
    done = 0
    for k, line in enumerate(fh, start=1):
        done += len(line)
        if k % every == 0:
            bar.update(done - bar.n)
        yield line
    bar.update(done - bar.n)


def _expected_columns(path: Path, header: list[str]) -> tuple[str, ...]:
    """The documented columns for this file: by its v1.0 name, else by the header's shape."""
    if path.stem.startswith("vehicle_tracks_"):
        return VEHICLE_COLUMNS
    if path.stem.startswith("pedestrian_tracks_"):
        return PEDESTRIAN_COLUMNS
    if path.stem.endswith(("_train", "_val", "_test")) or "case_id" in header:
        return CASE_COLUMNS
    if not ({"psi_rad", "length", "width"} & set(header)) and len(header) <= 8:
        return PEDESTRIAN_COLUMNS
    return VEHICLE_COLUMNS


def _check_header(path: Path, header: list[str]) -> tuple[str, ...]:
    """The file's columns if they are the documented ones in the documented order."""
    expected = _expected_columns(path, header)
    missing = [c for c in expected if c not in header]
    if missing:
        raise TrackFileError(f"{path}:1: header is missing column {missing[0]!r} "
                             f"(expected {','.join(expected)})")
    for index, (found, wanted) in enumerate(zip(header, expected, strict=False), start=1):
        if found != wanted:
            raise TrackFileError(
                f"{path}:1: column {index} is {found!r} where {wanted!r} is expected "
                f"(columns reordered; expected order {','.join(expected)})")
    for index, extra in enumerate(header[len(expected):], start=len(expected) + 1):
        if extra not in OPTIONAL_TRAILING:
            raise TrackFileError(f"{path}:1: column {index} {extra!r} is not a documented column")
    return tuple(header)


def _number(path: Path, line: int, column: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise TrackFileError(f"{path}:{line}: column {column!r}: expected a number, "
                             f"found {text!r}") from None
    if not math.isfinite(value):
        raise TrackFileError(f"{path}:{line}: column {column!r}: {text!r} is not finite")
    return value


def _integer(path: Path, line: int, column: str, text: str) -> int:
    value = _number(path, line, column, text)
    if value != int(value):
        raise TrackFileError(f"{path}:{line}: column {column!r}: expected an integer, "
                             f"found {text!r}")
    return int(value)


@dataclass
class _Columns:
    """Parsed rows column by column (compact for files with millions of rows)."""

    ids: array = field(default_factory=lambda: array("q"))  # case, track, frame, line
    values: array = field(default_factory=lambda: array("d"))  # x, y, vx, vy, psi, len, wid
    types: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.types)


def _parse_rows(path: Path, reader, columns: tuple[str, ...]) -> _Columns:
    """Validate every data row; keep (case, track, frame, line) and the 7 numeric values."""
    index = {name: k for k, name in enumerate(columns)}
    has_shape = "psi_rad" in index
    out = _Columns()
    interned: dict[str, str] = {}
    for line, cells in enumerate(reader, start=2):
        if not cells or (len(cells) == 1 and not cells[0].strip()):
            continue
        if len(cells) != len(columns):
            raise TrackFileError(f"{path}:{line}: expected {len(columns)} fields, "
                                 f"found {len(cells)}")

        def cell(name: str, _cells=cells) -> str:
            return _cells[index[name]].strip()

        case = _integer(path, line, "case_id", cell("case_id")) if "case_id" in index else 0
        agent_type = cell("agent_type")
        if not agent_type:
            raise TrackFileError(f"{path}:{line}: column 'agent_type' is empty")
        stamp = _integer(path, line, "timestamp_ms", cell("timestamp_ms"))
        if stamp % FRAME_MS:
            raise TrackFileError(f"{path}:{line}: column 'timestamp_ms': {stamp} is not on the "
                                 f"{FRAME_MS} ms grid (10 Hz)")
        _integer(path, line, "frame_id", cell("frame_id"))
        values = [_number(path, line, c, cell(c)) for c in ("x", "y", "vx", "vy")]
        shape = [math.nan] * 3
        if has_shape:
            for k, name in enumerate(("psi_rad", "length", "width")):
                text = cell(name)
                if text or agent_type not in NON_VEHICLE_TYPES:
                    shape[k] = _number(path, line, name, text)
        out.ids.extend((case, _integer(path, line, "track_id", cell("track_id")),
                        stamp // FRAME_MS, line))
        out.values.extend(values + shape)
        out.types.append(interned.setdefault(agent_type, agent_type))
    return out


def _plain_rows(path: Path, columns: tuple[str, ...]) -> _Columns | None:
    """`_parse_rows`' result, parsed column by column, for a plain file (no quotes, `\n` line
    ends) whose every row is valid; None if any is not (or may not be): then `_parse_rows`
    reads the file and names the first problem. Numbers go through float() as there."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:  # line ends as they are
            text = fh.read()
    except UnicodeDecodeError:
        return None
    if '"' in text or "\r" in text:
        return None
    lines = text.split("\n")
    numbers = [k + 1 for k in range(1, len(lines)) if lines[k].strip()]  # 1-based
    rows = [lines[n - 1] for n in numbers]
    if not rows:
        return _Columns()
    if any(row.count(",") != len(columns) - 1 for row in rows):
        return None
    cells = np.array(",".join(rows).split(","), dtype=object).reshape(len(rows), len(columns))
    parsed = _plain_values(cells, {name: k for k, name in enumerate(columns)})
    if parsed is None:
        return None
    ids, values, types = parsed
    out = _Columns(types=types)
    out.ids.frombytes(np.column_stack([ids, numbers]).astype(np.int64).tobytes())
    out.values.frombytes(values.tobytes())
    return out


def _plain_values(cells: np.ndarray, index: dict[str, int]):
    """(case, track, frame) [N, 3], the 7 values [N, 7] and the agent types of valid rows;
    None if a cell is not what `_parse_rows` accepts."""
    types = [cell.strip() for cell in cells[:, index["agent_type"]]]
    if not all(types):
        return None
    numeric = {}
    for name in ("track_id", "frame_id", "timestamp_ms", "x", "y", "vx", "vy",
                 *(["case_id"] if "case_id" in index else [])):
        numeric[name] = _floats(cells[:, index[name]])
        if numeric[name] is None or not np.isfinite(numeric[name]).all():
            return None
    for name in ("track_id", "frame_id", "timestamp_ms", "case_id"):
        value = numeric.get(name)
        if value is not None and (np.any(value != np.trunc(value))
                                  or np.any(np.abs(value) > 2.0**62)):
            return None
    stamps = numeric["timestamp_ms"].astype(np.int64)
    if np.any(stamps % FRAME_MS):
        return None
    shape = np.full((len(cells), 3), math.nan)
    if "psi_rad" in index:
        loose = np.array([t in NON_VEHICLE_TYPES for t in types])
        for k, name in enumerate(("psi_rad", "length", "width")):
            texts = cells[:, index[name]]
            empty = np.array([not t.strip() for t in texts])
            if np.any(empty & ~loose):
                return None
            value = _floats(np.where(empty, "nan", texts))
            if value is None or not np.isfinite(value[~empty]).all():
                return None
            shape[:, k] = value
    interned: dict[str, str] = {}
    case = numeric["case_id"] if "case_id" in numeric else np.zeros(len(cells))
    ids = np.column_stack([case, numeric["track_id"]]).astype(np.int64)
    values = np.column_stack([numeric[c] for c in ("x", "y", "vx", "vy")] + [shape])
    return (np.column_stack([ids, stamps // FRAME_MS]), np.ascontiguousarray(values),
            [interned.setdefault(t, t) for t in types])


def _floats(texts: np.ndarray) -> np.ndarray | None:
    """float() of every cell, or None if one is not a number."""
    try:
        return np.array([float(text) for text in texts], dtype=np.float64)
    except ValueError:
        return None


def _group_tracks(path: Path, cols: _Columns, has_case: bool) -> list[Recording]:
    ids = np.frombuffer(cols.ids, dtype=np.int64).reshape(-1, 4)
    values = np.frombuffer(cols.values, dtype=np.float64).reshape(-1, 7)
    order = np.lexsort((ids[:, 2], ids[:, 1], ids[:, 0]))  # by case, track, frame
    ids, values = ids[order], values[order]
    types = [cols.types[k] for k in order]
    key_change = np.flatnonzero(np.any(np.diff(ids[:, :2], axis=0) != 0, axis=1)) + 1
    bounds = np.concatenate([[0], key_change, [len(ids)]])
    by_case: dict[int, list[Track]] = {}
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        track = _track(path, ids[lo:hi], values[lo:hi], types[lo:hi])
        by_case.setdefault(int(ids[lo, 0]), []).append(track)
    return [Recording(f"{path.stem}#case{case}" if has_case else path.stem, path, tracks)
            for case, tracks in by_case.items()]


def _track(path: Path, ids: np.ndarray, values: np.ndarray, types: list[str]) -> Track:
    """One track's rows (sorted by frame) -> Track, after consistency checks."""
    frames = ids[:, 2]
    repeated = np.flatnonzero(np.diff(frames) == 0)
    if len(repeated):
        row = ids[repeated[0] + 1]
        raise TrackFileError(f"{path}:{row[3]}: column 'timestamp_ms': track {row[1]} has "
                             f"two rows at {row[2] * FRAME_MS} ms")
    if len(set(types)) > 1:
        raise TrackFileError(f"{path}:{ids[0, 3]}: column 'agent_type': track {ids[0, 1]} "
                             f"has several types {sorted(set(types))}")
    return Track(track_id=int(ids[0, 1]), agent_type=types[0], frames=frames.copy(),
                 xy=values[:, 0:2].copy(), v=values[:, 2:4].copy(), psi=values[:, 4].copy(),
                 length_m=float(values[0, 5]), width_m=float(values[0, 6]))


# ---------------------------------------------------------------- the devkit's validation list


OFFICIAL_VAL_LIST = "validation-set-list_INTERACTION-dataset_v1.txt"


def official_val_recordings(data_dir: Path, scenario: str) -> list[str]:
    """v1.0 recordings the devkit lists as validation for `scenario` (empty if no list).

    The list sits in recorded_trackfiles/ of the devkit's folder layout: a scenario name on
    one line, then its vehicle_tracks_NNN names, blocks separated by blank lines."""
    path = Path(data_dir) / "recorded_trackfiles" / OFFICIAL_VAL_LIST
    if not path.is_file():
        return []
    names, current = [], None
    for line in path.read_text().splitlines():
        word = line.strip()
        if not word:
            current = None
        elif current is None:
            current = word
        elif current == scenario:
            names.append(word)
    return names


def check_listed_present(data_dir: Path, scenario: str, listed: list[str],
                         present: list[str], switch: str) -> None:
    """PartialDownload naming the listed recordings absent from the copy and what to do."""
    missing = sorted(set(listed) - set(present))
    if not missing:
        return
    shown = ", ".join(missing[:5]) + (", ..." if len(missing) > 5 else "")
    path = Path(data_dir) / "recorded_trackfiles" / OFFICIAL_VAL_LIST
    raise PartialDownload(
        f"{path}: {len(missing)} of the {len(listed)} {scenario} recordings this validation "
        f"list holds out are not in {path.parent / scenario}: {shown} ({len(present)} "
        f"recordings are there: a partial download?), so the list cannot hold them out. "
        f"Add the missing files; or remove the list, and each recording's last part is held "
        f"out instead; or keep the list and set {switch} to do the same")
