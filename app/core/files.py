"""Writing files and hashing them, one module for every pipeline step and the analysis.

Atomic, reproducible output (JSON with sorted keys, npz with fixed zip timestamps, gzip
without a name or mtime: equal data gives equal bytes) and the SHA-256 content hashes that
tie bundles, checkpoints and trajectory files to what they were made from. Only numpy.
"""

import gzip
import hashlib
import io
import json
import os
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Protocol

import numpy as np

_FIXED_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary sibling path; rename it onto `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.tmp-{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(path: Path, data: object) -> None:
    """Write JSON atomically with sorted keys (numpy values as numbers and lists, paths as
    text), so equal data gives equal bytes."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def write_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """Write an .npz atomically and byte-reproducibly (fixed zip timestamps, sorted names)."""
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_FIXED_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, buf.getvalue())


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of bytes."""
    return hashlib.sha256(data).hexdigest()


def json_sha256(data: object) -> str:
    """Hex SHA-256 of `data` as canonical JSON (sorted keys, no spaces): key order and
    layout do not count."""
    return sha256_bytes(json.dumps(data, sort_keys=True, separators=(",", ":")).encode())


def write_gzip(path: Path, data: bytes) -> None:
    """Gzip `data` into `path` atomically and byte-reproducibly (no name, mtime 0)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


def read_bytes(path: Path) -> bytes:
    """A file's bytes, gunzipped if its name ends in .gz."""
    raw = Path(path).read_bytes()
    return gzip.decompress(raw) if Path(path).suffix == ".gz" else raw


class TrajectoryArrays(Protocol):
    """What `trajectory_hash` reads of a trajectory set (app/data/trajectory.py)."""

    positions: np.ndarray
    lengths: np.ndarray
    labels: Mapping[str, np.ndarray]
    held_out: np.ndarray | None


def trajectory_hash(trajs: TrajectoryArrays) -> str:
    """sha256 hex of a TrajectorySet's arrays: ties a checkpoint to its training data (and,
    for a recorded world, to the recordings it held out)."""
    digest = hashlib.sha256()
    labels = trajs.labels
    for array in (trajs.positions, trajs.lengths, *(labels[k] for k in sorted(labels))):
        digest.update(np.ascontiguousarray(array).tobytes())
    if trajs.held_out is not None:
        digest.update(np.ascontiguousarray(trajs.held_out, dtype=bool).tobytes())
    return digest.hexdigest()
