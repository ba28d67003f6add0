"""A lab's own robot logs: one documented generic CSV format, read into recordings.

Columns (a header line is required; these names, in this order):
  recording      optional first column; without it a file is one recording named after its stem
  agent_id       the agent's id: a non-empty string of at most 64 characters
  time_s         time [s]
  x_m, y_m       position [m] in any fixed planar frame, y up as on a map
  vx_mps, vy_mps velocity [m/s]; both cells empty: the position difference over the time step,
                 centred where the samples one step before and after exist, else one-sided
  role           robot, human, or another lower-case word (pedestrian, ...): kept, never paired
  heading_rad, length_m, width_m   optional trailing columns, in this order; cells may be empty

A path is one file or a folder of .csv files (read in name order); a recording lies in one
file. The time step dt is the most common positive difference between consecutive samples of
an agent (rounded to the microsecond), the same in every recording; every time lies a whole
number of steps (within 1% of dt) from its recording's first time. Missing samples are gaps.
Every format problem raises `RecordingError` naming file, line and column, and nothing is
returned until every file has been read and checked.

A line file (optional: walls, kerbs, lane marks to draw under the agents) has the columns
line_id, kind (a lanelet2 line type the scene draws, e.g. wall, curbstone, line_thin,
stop_line), dashed (1/0, true/false), x_m, y_m: one row per point, in order along the line.
"""

import math
import re
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from app.core.files import sha256_file
from app.recordings.lanelet_map import LaneLine
from app.recordings.scene import LINE_KINDS
from app.recordings.tracks import Recording, Track, TrackFileError, csv_reader

LEADING = "recording"
COLUMNS = ("agent_id", "time_s", "x_m", "y_m", "vx_mps", "vy_mps", "role")
TRAILING = ("heading_rad", "length_m", "width_m")
ORDER = f"[{LEADING},]{','.join(COLUMNS)}[,{','.join(TRAILING)}]"
ROBOT, HUMAN = "robot", "human"
ROLE_WORD = re.compile(r"[a-z][a-z0-9_/-]*")
ROLES_EXPECTED = "robot, human or another lower-case word such as pedestrian"
MAX_ID_CHARS = 64
DT_DECIMALS = 6  # the time step is rounded to the microsecond
GRID_TOLERANCE = 0.01  # a time may lie this share of dt off its grid step
LINE_COLUMNS = ("line_id", "kind", "dashed", "x_m", "y_m")  # a line file: lines to draw
DASHED = {"1": True, "true": True, "0": False, "false": False}


class RecordingError(TrackFileError):
    """A lab's CSV log breaks the documented format; the message names file, line and column."""


@dataclass
class Logs:
    """The recordings read from a path of lab logs, their one time step and the files' hashes."""

    recordings: list[Recording]
    dt_s: float
    files: dict[str, str]  # file name (relative to the folder read) -> sha256, reading order


@dataclass
class _Agent:
    """One agent's rows as read: lines, times and x, y, vx, vy, heading (NaN: empty cell)."""

    name: str
    role: str
    line: int
    lines: array = field(default_factory=lambda: array("q"))
    times: array = field(default_factory=lambda: array("d"))
    values: array = field(default_factory=lambda: array("d"))
    sizes: dict[str, tuple[float, int]] = field(default_factory=dict)  # column -> (m, line)


@dataclass
class _Log:
    """One recording's agents (in order of first appearance) and the file and line it starts."""

    name: str
    path: Path
    line: int
    agents: dict[str, _Agent] = field(default_factory=dict)


def _error(path: Path, line: int, column: str | int, what: str) -> RecordingError:
    shown = repr(column) if isinstance(column, str) else column
    return RecordingError(f"{path}:{line}: column {shown}: {what}")


# ---------------------------------------------------------------- the whole path


def read_logs(path: Path) -> Logs:
    """Read and check a lab's CSV log file or folder of them into recordings on one time grid."""
    files = log_files(path)
    logs: dict[str, _Log] = {}
    for file in tqdm(files, desc="logs", unit="file", leave=False, disable=len(files) < 2):
        _read_file(file, logs)
    dt = _time_step(list(logs.values()))
    recordings = [_recording(log, dt) for log in logs.values()]
    folder = Path(path) if Path(path).is_dir() else Path(path).parent
    return Logs(recordings, dt, {f.relative_to(folder).as_posix(): sha256_file(f) for f in files})


def log_files(path: Path) -> list[Path]:
    """The file itself, or a folder's .csv files in name order."""
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() == ".csv" and p.is_file())
        if not files:
            raise RecordingError(f"{path}: no .csv files in this folder")
        return files
    if not path.is_file():
        raise RecordingError(f"{path}: no such file or folder")
    return [path]


# ---------------------------------------------------------------- one file


def _read_file(path: Path, logs: dict[str, _Log]) -> None:
    """Check one file's header and rows and add its rows to `logs`."""
    for line, row in _rows(path, _check_header, ORDER):
        _read_row(path, line, row, logs)


def _rows(path: Path, check_header, expected: str) -> Iterator[tuple[int, dict[str, str]]]:
    """Each data row of a file as (line, column -> stripped cell), once its header is checked."""
    with csv_reader(path, encoding="utf-8-sig") as reader:  # -sig: Excel's byte order mark
        header = next(reader, None)
        if header is None or not any(cell.strip() for cell in header):
            raise RecordingError(f"{path}:1: empty file: expected a header line {expected}")
        columns = check_header(path, [cell.strip() for cell in header])
        count = 0
        for cells in reader:
            if cells and (len(cells) > 1 or cells[0].strip()):
                yield reader.line_num, _fields(path, reader.line_num, columns, cells)
                count += 1
    if not count:
        raise RecordingError(f"{path}:2: no data rows after the header")


def _fields(path: Path, line: int, columns: tuple[str, ...], cells: list[str]) -> dict[str, str]:
    """The row's stripped cells by column, if it has as many as the header."""
    if len(cells) < len(columns):
        raise _error(path, line, columns[len(cells)], f"missing: the row has {len(cells)} "
                                                      f"fields where the header has {len(columns)}")
    if len(cells) > len(columns):
        raise _error(path, line, len(columns) + 1, f"the row has {len(cells)} fields where the "
                     f"header has {len(columns)} (quote a value that holds a comma)")
    return dict(zip(columns, (cell.strip() for cell in cells), strict=True))


def _check_header(path: Path, header: list[str]) -> tuple[str, ...]:
    """The file's columns if they are the documented ones in the documented order."""
    expected = ((LEADING,) if header[0] == LEADING else ()) + COLUMNS
    for name in expected:
        if name not in header:
            raise _error(path, 1, name, f"missing from the header (expected {ORDER})")
    for index, (found, wanted) in enumerate(zip(header, expected, strict=False), start=1):
        if found not in (LEADING, *COLUMNS, *TRAILING):
            raise _error(path, 1, found, f"not a documented column (column {index} of the "
                                         f"header; expected {ORDER})")
        if found != wanted:
            raise _error(path, 1, found, f"found as column {index} where {wanted!r} is "
                                         f"expected (columns reordered; expected {ORDER})")
    _check_trailing(path, header[len(expected):], len(expected))
    return tuple(header)


def _check_trailing(path: Path, names: list[str], before: int) -> None:
    """After `role` only heading_rad, length_m, width_m may follow, each once, in that order."""
    last = -1
    for index, name in enumerate(names, start=before + 1):
        if name not in TRAILING:
            raise _error(path, 1, name, f"not a documented column (column {index} of the "
                                        f"header; after 'role' only {', '.join(TRAILING)} "
                                        f"may follow)")
        if TRAILING.index(name) <= last:
            raise _error(path, 1, name, f"column {index} of the header repeats or reorders "
                                        f"the optional columns (expected "
                                        f"{', '.join(TRAILING)}, in this order)")
        last = TRAILING.index(name)


def _read_row(path: Path, line: int, row: dict[str, str], logs: dict[str, _Log]) -> None:
    """Check one data row and add it to its agent."""
    log = _log_of(path, line, row, logs)
    agent = _agent_of(path, line, row, log)
    agent.lines.append(line)
    agent.times.append(_number(path, line, "time_s", row["time_s"]))
    agent.values.extend(_values(path, line, row))
    for column in ("length_m", "width_m"):
        _check_size(path, line, column, row.get(column, ""), agent)


def _log_of(path: Path, line: int, row: dict[str, str], logs: dict[str, _Log]) -> _Log:
    """The row's recording, which must not also lie in another file."""
    name = row.get(LEADING, path.stem)
    if not name:
        raise _error(path, line, LEADING, "empty: every row names its recording")
    log = logs.setdefault(name, _Log(name, path, line))
    if log.path != path:
        raise _error(path, line, LEADING, f"recording {name!r} is also in {log.path} (line "
                     f"{log.line}): a recording lies in one file (a file without a "
                     f"{LEADING!r} column is one recording named after the file)")
    return log


def _agent_of(path: Path, line: int, row: dict[str, str], log: _Log) -> _Agent:
    """The row's agent in its recording; an agent keeps one role."""
    name, role = row["agent_id"], row["role"]
    if not name or len(name) > MAX_ID_CHARS:
        found = f"{len(name)} characters" if name else "empty"
        raise _error(path, line, "agent_id", f"{found}: expected an id of 1 to {MAX_ID_CHARS} "
                                             f"characters")
    if not ROLE_WORD.fullmatch(role):
        raise _error(path, line, "role", f"{role!r} is not a role: expected {ROLES_EXPECTED}")
    agent = log.agents.setdefault(name, _Agent(name, role, line))
    if agent.role != role:
        raise _error(path, line, "role", f"agent {name!r} is {role!r} here but {agent.role!r} "
                                         f"at line {agent.line}: an agent keeps one role")
    return agent


def _number(path: Path, line: int, column: str, text: str, empty_ok: bool = False) -> float:
    """The cell's finite value (NaN for an empty cell where that is allowed)."""
    if not text:
        if empty_ok:
            return np.nan
        raise _error(path, line, column, "empty: expected a number")
    try:
        value = float(text)
    except ValueError:
        raise _error(path, line, column, f"expected a number, found {text!r}") from None
    if not math.isfinite(value):
        raise _error(path, line, column, f"{text!r} is not finite: expected a number")
    return value


def _values(path: Path, line: int, row: dict[str, str]) -> list[float]:
    """x, y, vx, vy, heading of one row (vx, vy both empty or both numbers; heading optional)."""
    if bool(row["vx_mps"]) != bool(row["vy_mps"]):
        empty = "vx_mps" if not row["vx_mps"] else "vy_mps"
        raise _error(path, line, empty, "empty while the other velocity cell is not: give "
                                        "vx_mps and vy_mps, or leave both empty")
    values = [_number(path, line, c, row[c], empty_ok=c.startswith("v"))
              for c in ("x_m", "y_m", "vx_mps", "vy_mps")]
    return [*values, _number(path, line, "heading_rad", row.get("heading_rad", ""), True)]


def _check_size(path: Path, line: int, column: str, text: str, agent: _Agent) -> None:
    """A length or width is positive and the same in every row of the agent that gives one."""
    size = _number(path, line, column, text, empty_ok=True)
    if np.isnan(size):
        return
    if size <= 0:
        raise _error(path, line, column, f"{text!r}: expected a positive size in metres")
    first, first_line = agent.sizes.setdefault(column, (size, line))
    if size != first:
        raise _error(path, line, column, f"agent {agent.name!r} is {text} m here but {first} m "
                                         f"at line {first_line}: one size per agent")


# ---------------------------------------------------------------- the time grid


def _time_step(logs: list[_Log]) -> float:
    """The one time step of every recording (each recording's most common step)."""
    found: tuple[float, _Log] | None = None
    for log in logs:
        step = _log_step(log)
        if step is None:
            continue
        if found is None:
            found = (step[0], log)
        elif step[0] != found[0]:
            raise _error(log.path, step[1], "time_s", f"recording {log.name!r} steps by "
                         f"{step[0]} s where recording {found[1].name!r} ({found[1].path}) steps "
                         f"by {found[0]} s: every file and recording must share one time step")
    if found is None:
        raise _error(logs[0].path, logs[0].line, "time_s", "no agent has two samples at "
                     "different times, so the time step cannot be inferred")
    return found[0]


def _log_step(log: _Log) -> tuple[float, int] | None:
    """(dt, the first line that steps by dt) of one recording, None if no agent ever steps."""
    steps, lines = [], []
    for agent in log.agents.values():
        times = np.asarray(agent.times)
        order = np.argsort(times, kind="stable")
        diff = np.round(np.diff(times[order]), DT_DECIMALS)
        steps.append(diff[diff > 0])
        lines.append(np.asarray(agent.lines)[order[1:]][diff > 0])
    steps, lines = np.concatenate(steps), np.concatenate(lines)
    if not len(steps):
        return None
    values, counts = np.unique(steps, return_counts=True)
    dt = float(values[np.argmax(counts)])
    return dt, int(lines[steps == dt].min())


class _Rows(NamedTuple):
    """One agent's rows in time order: grid index, steps from the start, line, time, values."""

    frames: np.ndarray
    steps: np.ndarray
    lines: np.ndarray
    times: np.ndarray
    values: np.ndarray  # [N, 5] x, y, vx, vy, heading


_Failure = tuple[int, str, str] | None  # (line, column, what is wrong) or None


def _recording(log: _Log, dt: float) -> Recording:
    """One recording's tracks on the grid of dt from its first time, after the grid checks."""
    start = min(min(agent.times) for agent in log.agents.values())
    rows = {name: _grid_rows(agent, start, dt) for name, agent in log.agents.items()}
    for check in (_off_grid, _repeated_time, _lonely_velocity):
        found = [f for name, agent in log.agents.items() if (f := check(agent, rows[name], dt))]
        if found:
            raise _error(log.path, *min(found))
    tracks = [_track(k, agent, rows[agent.name], dt)
              for k, agent in enumerate(log.agents.values(), start=1)]
    return Recording(log.name, log.path, tracks)


def _grid_rows(agent: _Agent, start: float, dt: float) -> _Rows:
    """The agent's rows sorted by grid index (then line), with their unrounded steps."""
    times = np.asarray(agent.times)
    steps = (times - start) / dt
    frames = np.rint(steps).astype(np.int64)
    lines = np.asarray(agent.lines)
    order = np.lexsort((lines, frames))
    values = np.asarray(agent.values).reshape(-1, 5)
    return _Rows(frames[order], steps[order], lines[order], times[order], values[order])


def _off_grid(agent: _Agent, rows: _Rows, dt: float) -> _Failure:
    """The agent's earliest row whose time is not a whole number of steps from the start."""
    off = np.flatnonzero(np.abs(rows.steps - rows.frames) > GRID_TOLERANCE)
    if not len(off):
        return None
    k = off[np.argmin(rows.lines[off])]
    time = rows.times[k]
    start = time - rows.steps[k] * dt
    return (int(rows.lines[k]), "time_s",
            f"{time:g} s is {rows.steps[k]:.3f} steps of {dt} s after the recording's first "
            f"time {start:g} s: every time must be a whole number of steps (within 1%); put "
            f"logs with jittered clocks on a regular grid first")


def _repeated_time(agent: _Agent, rows: _Rows, dt: float) -> _Failure:
    """The agent's earliest row at a grid time it already has."""
    same = np.flatnonzero(np.diff(rows.frames) == 0)
    if not len(same):
        return None
    k = same[np.argmin(rows.lines[same + 1])]
    return (int(rows.lines[k + 1]), "time_s",
            f"agent {agent.name!r} has two rows at {rows.times[k + 1]:g} s (the other is line "
            f"{rows.lines[k]}): one row per agent and time")


def _neighbours(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether the sample one step before, and the one one step after, exist."""
    step = np.diff(frames) == 1
    return np.r_[False, step], np.r_[step, False]


def _lonely_velocity(agent: _Agent, rows: _Rows, dt: float) -> _Failure:
    """The agent's earliest row with empty velocity cells and no neighbour to take it from."""
    before, after = _neighbours(rows.frames)
    alone = np.flatnonzero(np.isnan(rows.values[:, 2]) & ~before & ~after)
    if not len(alone):
        return None
    return (int(rows.lines[alone].min()), "vx_mps",
            f"empty, and agent {agent.name!r} has no sample one step before or after this one "
            f"to take its velocity from: give vx_mps and vy_mps here")


# ---------------------------------------------------------------- tracks


def _track(track_id: int, agent: _Agent, rows: _Rows, dt: float) -> Track:
    """The agent's rows in time order as a Track, empty velocities filled from positions."""
    sizes = [agent.sizes.get(c, (np.nan, 0))[0] for c in ("length_m", "width_m")]
    return Track(track_id=track_id, agent_type=agent.role, frames=rows.frames.copy(),
                 xy=rows.values[:, 0:2].copy(), v=_filled_velocity(rows, dt),
                 psi=rows.values[:, 4].copy(), length_m=float(sizes[0]),
                 width_m=float(sizes[1]), name=agent.name)


def _filled_velocity(rows: _Rows, dt: float) -> np.ndarray:
    """vx, vy as given; an empty pair is the centred (else one-sided) position difference / dt."""
    xy, v = rows.values[:, 0:2], rows.values[:, 2:4].copy()
    before, after = _neighbours(rows.frames)
    lo = np.where(before[:, None], np.roll(xy, 1, axis=0), xy)
    hi = np.where(after[:, None], np.roll(xy, -1, axis=0), xy)
    span = (before.astype(int) + after.astype(int))[:, None] * dt
    missing = np.isnan(v[:, 0])
    v[missing] = ((hi - lo) / np.maximum(span, dt))[missing]
    return v


# ---------------------------------------------------------------- lines to draw


@dataclass
class _Line:
    """One line of a line file: its kind, style, first line in the file and points."""

    name: str
    kind: str
    dashed: bool
    line: int
    points: list[tuple[float, float]] = field(default_factory=list)


def read_line_file(path: Path) -> list[LaneLine]:
    """Lines to draw under a lab's logs (walls, kerbs, lane marks) from a CSV of their points."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such file (the lines to draw: "
                             f"{','.join(LINE_COLUMNS)})")
    lines: dict[str, _Line] = {}
    for line, row in _rows(path, _check_line_header, ",".join(LINE_COLUMNS)):
        _add_point(path, line, row, lines)
    for entry in lines.values():
        if len(entry.points) < 2:
            raise _error(path, entry.line, "line_id", f"line {entry.name!r} has one point: a "
                                                      f"line needs two or more")
    return [LaneLine(e.kind, "dashed" if e.dashed else "solid", np.array(e.points))
            for e in lines.values()]


def _check_line_header(path: Path, header: list[str]) -> tuple[str, ...]:
    """The line file's columns if they are exactly LINE_COLUMNS."""
    expected = f"expected {','.join(LINE_COLUMNS)}"
    for name in LINE_COLUMNS:
        if name not in header:
            raise _error(path, 1, name, f"missing from the header ({expected})")
    for index, found in enumerate(header, start=1):
        if index > len(LINE_COLUMNS):
            raise _error(path, 1, found, f"not a documented column (column {index} of the "
                                         f"header; {expected})")
        if found != LINE_COLUMNS[index - 1]:
            raise _error(path, 1, found, f"found as column {index} where "
                                         f"{LINE_COLUMNS[index - 1]!r} is expected ({expected}, "
                                         f"in this order)")
    return LINE_COLUMNS


def _add_point(path: Path, line: int, row: dict[str, str], lines: dict[str, _Line]) -> None:
    """Check one row of a line file and add its point to its line."""
    name, kind, dashed = row["line_id"], row["kind"], row["dashed"].lower()
    if not name:
        raise _error(path, line, "line_id", "empty: every row names its line")
    if kind not in LINE_KINDS:
        raise _error(path, line, "kind", f"{kind!r} is not a line kind: expected one of "
                                         f"{', '.join(LINE_KINDS)}")
    if dashed not in DASHED:
        raise _error(path, line, "dashed", f"expected 1, 0, true or false, found {dashed!r}")
    entry = lines.setdefault(name, _Line(name, kind, DASHED[dashed], line))
    if (entry.kind, entry.dashed) != (kind, DASHED[dashed]):
        column = "kind" if entry.kind != kind else "dashed"
        raise _error(path, line, column, f"line {name!r} is {row[column]!r} here but not at "
                                         f"line {entry.line}: one kind and style per line")
    entry.points.append((_number(path, line, "x_m", row["x_m"]),
                         _number(path, line, "y_m", row["y_m"])))
