"""`tomstudy reproduce` and `serve --archive`: an archive (archive.py) checked member by member,
its analysis re-run on this machine beside the archived numbers, its study set up to serve.

Every member must match ARCHIVE.json's SHA-256; an altered, damaged, missing or unlisted
member is refused by name, and so is a name that would land outside the folder it is
unpacked into. Numbers agree when they agree to the 10 significant digits the analysis's
CSVs are written with (a last-digit difference of another machine's arithmetic is not one).
"""

import csv
import json
import math
import shutil
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from app.bank.bundle import bundle_dir
from app.core.files import sha256_bytes, sha256_file
from app.researcher.archive import (
    ANALYSIS,
    ARCHIVE_MANIFEST,
    BUNDLE,
    ENVIRONMENT,
    FORMAT,
    STUDY,
    environment,
    run_archived_analysis,
)
from app.settings import Settings
from app.study.config import load_study_config

SIGNIFICANT_DIGITS = 10
IDENTIFIERS = ("_id", "_sha256")  # CSV columns compared as text
# the lab's own database, platform credentials and rate-limit store, which a reviewer's
# server never reads or counts in
LAB_ONLY_VARIABLES = ("TOMSTUDY_DATABASE_PASSWORD_FILE", "TOMSTUDY_PROLIFIC_TOKEN",
                      "TOMSTUDY_PROLIFIC_TOKEN_FILE", "TOMSTUDY_RATE_LIMIT_STORAGE")


class ArchiveError(ValueError):
    """An archive cannot be used as it is; the message names the file or member."""


def extract_verified(archive: Path, into: Path) -> dict:
    """Unpack every member of `archive` into `into` once all match ARCHIVE.json (ArchiveError
    naming each altered, damaged, missing or unlisted member otherwise); the manifest."""
    try:
        zf = zipfile.ZipFile(archive)
    except (OSError, zipfile.BadZipFile) as err:
        raise ArchiveError(f"{archive}: not a readable zip archive ({err})") from None
    with zf:
        manifest = read_manifest(zf, archive)
        unsafe = [n for n in zf.namelist() if not safe_member_name(n)]
        if unsafe:
            raise ArchiveError(f"{archive}: refused: {unsafe[0]}: not a relative path inside "
                               "the archive")
        members, problems = verified_bytes(zf, manifest["members"])
        if problems:
            raise ArchiveError(f"{archive}: refused: {'; '.join(problems)}")
    for name, data in members.items():
        (into / name).parent.mkdir(parents=True, exist_ok=True)
        (into / name).write_bytes(data)
    return manifest


def read_manifest(zf: zipfile.ZipFile, archive: Path) -> dict:
    """The archive's ARCHIVE.json (ArchiveError if missing, unreadable or of another format)."""
    try:
        manifest = json.loads(zf.read(ARCHIVE_MANIFEST))
    except KeyError:
        raise ArchiveError(f"{archive}: no {ARCHIVE_MANIFEST}; not a tomstudy archive") from None
    except (ValueError, zipfile.BadZipFile, zlib.error) as err:
        raise ArchiveError(f"{archive}: {ARCHIVE_MANIFEST}: unreadable ({err})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise ArchiveError(f"{archive}: {ARCHIVE_MANIFEST}: not a {FORMAT} manifest")
    return manifest


def safe_member_name(name: str) -> bool:
    """Whether a zip entry's name stays inside the folder it is unpacked into."""
    path = PurePosixPath(name)
    return bool(name) and not path.is_absolute() and ".." not in path.parts and "\\" not in name


def verified_bytes(zf: zipfile.ZipFile, listed: dict) -> tuple[dict[str, bytes], list[str]]:
    """(name -> bytes of every member matching its listed SHA-256, one problem per member that
    is altered, damaged, missing or not listed)."""
    present = set(zf.namelist()) - {ARCHIVE_MANIFEST}
    problems = [f"{n}: listed in {ARCHIVE_MANIFEST} but missing"
                for n in sorted(set(listed) - present)]
    problems += [f"{n}: not listed in {ARCHIVE_MANIFEST}" for n in sorted(present - set(listed))]
    members = {}
    for name in sorted(present & set(listed)):
        try:
            data = zf.read(name)
        except (zipfile.BadZipFile, zlib.error, EOFError) as err:
            problems.append(f"{name}: altered (its stored bytes are damaged: {err})")
            continue
        if sha256_bytes(data) != listed[name]["sha256"]:
            problems.append(f"{name}: altered (its SHA-256 is not {ARCHIVE_MANIFEST}'s)")
        else:
            members[name] = data
    return members, problems


# ---------------------------------------------------------------- reproduce

@dataclass(frozen=True)
class Number:
    """One reported number beside its recomputation; `where` names its file and place."""

    where: str
    archived: float
    recomputed: float

    @property
    def equal(self) -> bool:
        """Equal to the digits the reports are written with (NaN equals NaN)."""
        a, b = self.archived, self.recomputed
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return (_digits(a) == _digits(b)
                or math.isclose(a, b, rel_tol=10.0 ** -SIGNIFICANT_DIGITS, abs_tol=1e-12))

    def line(self) -> str:
        """`where  archived  recomputed  equal|DIFFERS`."""
        verdict = "equal" if self.equal else "DIFFERS"
        return f"{self.where:<72} {_digits(self.archived):>18} {_digits(self.recomputed):>18}  " \
               f"{verdict}"


def _digits(value: float) -> str:
    return f"{value:.{SIGNIFICANT_DIGITS}g}"


def reproduce(archive: Path, work: Path, say: Callable[[str], None] = print) -> bool:
    """Check every member of `archive`, re-run its analysis under `work` and `say` every
    reported number beside its recomputation; True when all agree."""
    root = work / "archive"
    manifest = extract_verified(archive, root)
    say(f"{archive}: SHA-256 {sha256_file(archive)}; all {len(manifest['members'])} members "
        f"match {ARCHIVE_MANIFEST} (study {manifest['study_id']}, written "
        f"{manifest['created_at']} by tomstudy {manifest['package_version']}, "
        f"{len(manifest['participant_ids'])} participants)")
    written, here = json.loads((root / ENVIRONMENT).read_text()), environment()
    say(f"archived on Python {written['python'].split()[0]} ({written['platform']}); "
        f"recomputed on Python {here['python'].split()[0]} ({here['platform']})")
    run_archived_analysis(root, manifest["study_id"], work / "recomputed")
    numbers, differences = compare_reports(root / ANALYSIS, work / "recomputed")
    say(f"{'number':<72} {'archived':>18} {'recomputed':>18}")
    for number in numbers:
        say(number.line())
    for difference in differences:
        say(f"DIFFERS {difference}")
    wrong = sum(not n.equal for n in numbers) + len(differences)
    say(f"{len(numbers)} numbers in {len(reported_files(root / ANALYSIS))} files: "
        + ("every one equal to its recomputation" if not wrong else
           f"{wrong} differ from their recomputation"))
    return wrong == 0


def reported_files(folder: Path) -> list[Path]:
    """The archived analysis files that hold numbers: summary.json and every CSV."""
    return sorted(p for p in folder.iterdir() if p.name == "summary.json" or p.suffix == ".csv")


def compare_reports(archived: Path, recomputed: Path) -> tuple[list[Number], list[str]]:
    """Every number of the archived analysis files beside the recomputed one, and every other
    difference (a missing file, a changed text or table shape)."""
    numbers: list[Number] = []
    differences: list[str] = []
    for path in reported_files(archived):
        again = recomputed / path.name
        if not again.is_file():
            differences.append(f"{path.name}: not written by the recomputation")
            continue
        compare = compare_json if path.suffix == ".json" else compare_csv
        found, other = compare(path, again)
        numbers += found
        differences += other
    return numbers, differences


def compare_json(archived: Path, recomputed: Path) -> tuple[list[Number], list[str]]:
    """Every leaf of two JSON files: numbers side by side, any other value that differs."""
    a = dict(leaves(json.loads(archived.read_text())))
    b = dict(leaves(json.loads(recomputed.read_text())))
    numbers, differences = [], []
    for key in sorted(set(a) | set(b)):
        if _is_number(a.get(key)) and _is_number(b.get(key)):
            numbers.append(Number(f"{archived.name} {key}", float(a[key]), float(b[key])))
        elif a.get(key) != b.get(key):
            differences.append(f"{archived.name} {key}: {a.get(key)!r} archived, "
                               f"{b.get(key)!r} recomputed")
    return numbers, differences


def leaves(value, path: str = "") -> Iterator[tuple[str, object]]:
    """(dotted path, value) of every non-container value in nested dicts and lists."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from leaves(item, f"{path}.{key}" if path else str(key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from leaves(item, f"{path}[{index}]")
    else:
        yield path, value


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def compare_csv(archived: Path, recomputed: Path) -> tuple[list[Number], list[str]]:
    """Every cell of two CSV tables: numbers side by side, any other cell that differs."""
    with open(archived, newline="") as fa, open(recomputed, newline="") as fb:
        rows_a, rows_b = list(csv.reader(fa)), list(csv.reader(fb))
    name = archived.name
    if len(rows_a) != len(rows_b) or (rows_a and rows_a[0] != rows_b[0]):
        return [], [f"{name}: {len(rows_a)} rows archived, {len(rows_b)} recomputed, or "
                    "other columns"]
    header = rows_a[0] if rows_a else []
    numbers, differences = [], []
    for index, (row_a, row_b) in enumerate(zip(rows_a[1:], rows_b[1:], strict=True), start=1):
        for column, cell_a, cell_b in zip(header, row_a, row_b, strict=True):
            x, y = _number(column, cell_a), _number(column, cell_b)
            if x is not None and y is not None:
                numbers.append(Number(f"{name} row {index} {column}", x, y))
            elif cell_a != cell_b:
                differences.append(f"{name} row {index} {column}: {cell_a!r} archived, "
                                   f"{cell_b!r} recomputed")
    return numbers, differences


def _number(column: str, cell: str) -> float | None:
    if column.endswith(IDENTIFIERS):  # an id of digits only is still text
        return None
    try:
        return float(cell)
    except ValueError:
        return None


# ---------------------------------------------------------------- serve --archive

def serving_environment(root: Path) -> dict[str, str]:
    """The variables that point a server at `root` (which must be new or empty): its configs
    and data dirs, and a fresh SQLite database in the data dir (DATABASE_URL empty)."""
    root = Path(root)
    if root.exists() and (not root.is_dir() or any(root.iterdir())):
        raise ArchiveError(f"--archive-dir: {root} is not an empty folder; serve --archive "
                           "sets the archived study up in a fresh one, never in a lab's data")
    return {"TOMSTUDY_CONFIGS_DIR": str(root / "configs"), "TOMSTUDY_DATA_DIR": str(root / "data"),
            "TOMSTUDY_RECORDINGS_DIR": str(root / "data" / "recordings"), "DATABASE_URL": ""}


def unpack_for_serving(archive: Path, settings: Settings) -> str:
    """Set the archived study up under `settings`' configs and data dirs (both new or empty):
    the bundle's configs with the archived study config, and the bundle where that config
    says; returns the study id."""
    for folder in (Path(settings.configs_dir), settings.layout.root):
        if folder.exists() and any(folder.iterdir()):
            raise ArchiveError(f"{folder}: not empty; serve --archive sets the archived study "
                               "up in fresh folders, never in a lab's")
    with tempfile.TemporaryDirectory(prefix="tomstudy-archive-") as tmp:
        members = Path(tmp)
        study_id = extract_verified(archive, members)["study_id"]
        shutil.copytree(members / BUNDLE / "configs", settings.configs_dir, dirs_exist_ok=True)
        shutil.copyfile(members / STUDY / f"{study_id}.yaml",
                        Path(settings.configs_dir) / f"{study_id}.yaml")
        config = load_study_config(settings, study_id)
        shutil.copytree(members / BUNDLE, bundle_dir(config, study_id, settings.configs_dir,
                                                     settings.layout))
    settings.layout.root.mkdir(parents=True, exist_ok=True)
    return study_id
