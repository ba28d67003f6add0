"""`tomstudy archive`: one zip holding a study, its data and its analysis, for a reviewer.

    ARCHIVE.json             format, study, time, tomstudy version, the SHA-256 and size of
                             every other member, the public participant ids it holds and
                             what it withholds
    bundle/...               the frozen bundle the study is served from (app/bank/bundle.py)
    study/<study>.yaml       the study config it is served and analysed with
    exports/<what>.csv       predictions, survey, events and participants, pseudonymous: no
                             platform id or completion code, no free-text answer unless asked
    exports/<what>.datapackage.json   each export's codebook (analysis/codebook.py)
    analysis/                `tomstudy analyze` of exports/predictions.csv: summary.json and
                             every CSV (each number the report shows), and report.html
    prereg/preregistration.{md,html}   `tomstudy prereg`: the preregistration
    environment.json         Python, the platform and every installed distribution's version

Each member comes from one writer of MEMBER_WRITERS, called in order on a staging folder;
adding a member is adding a writer. The zip is written atomically and entered in the data
dir's registry (archive_registry.py), so a later withdrawal names it. reproduce.py checks an
archive, re-runs its analysis and sets its study up to be served.
"""

import importlib.metadata
import platform
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd
from sqlalchemy.engine import Engine
from sqlmodel import Session

from analysis.exports import read_export
from analysis.load import load_csv
from analysis.report import analyze
from app import __version__
from app.bank.served import bundle_inputs, served_bundle
from app.bank.verify import open_bundle
from app.configio import load_yaml_model
from app.core.contracts import WHAT, StudyInputs
from app.core.csvsafe import write_csv
from app.core.files import atomic_path, sha256_file, write_json
from app.prereg.write import write_prereg
from app.researcher.archive_registry import read_registry, record_archive
from app.researcher.exports import export_table, write_export_package
from app.settings import Settings
from app.study.config import StudyConfig, study_config_path

FORMAT = "tomstudy-archive-v1"
ARCHIVE_MANIFEST = "ARCHIVE.json"
BUNDLE = "bundle"
STUDY = "study"
EXPORTS = "exports"
ANALYSIS = "analysis"
PREREG = "prereg"
ENVIRONMENT = "environment.json"
# what the archived analysis says its rows came from: the same in the archive and on reproduce
ANALYSIS_SOURCE = f"{EXPORTS}/predictions.csv"
# columns no archive holds: the platform's id of the person and the code they handed in
WITHHELD_COLUMNS = {"participants": ["external_id", "completion_code"]}
# survey answers kept without --with-free-text: those picked from the study's own scale or
# options (a question's kind is "" once it left the config, so it is left out too)
CLOSED_KINDS = ("likert", "choice")


@dataclass(frozen=True)
class ArchiveJob:
    """What one archive is made of: the study, where its data is, and whether free text goes."""

    settings: Settings
    study_id: str
    engine: Engine  # the study database (DATABASE_URL)
    config: StudyConfig
    with_free_text: bool = False


def write_bundle(job: ArchiveJob, staging: Path) -> None:
    """bundle/: the verified bundle the study is served from, file for file."""
    shutil.copytree(served_bundle(job.settings, job.study_id).root, staging / BUNDLE)


def write_study_config(job: ArchiveJob, staging: Path) -> None:
    """study/<study>.yaml: the live study config (texts and exclusions may differ from the
    bundle's frozen copy; what shapes the bank may not)."""
    target = staging / STUDY / f"{job.study_id}.yaml"
    target.parent.mkdir(parents=True)
    shutil.copyfile(study_config_path(job.settings, job.study_id), target)


def write_exports(job: ArchiveJob, staging: Path) -> None:
    """exports/<what>.csv: every export, without platform ids (and free text unless asked),
    each with its codebook beside it (<what>.datapackage.json, of the columns it holds)."""
    (staging / EXPORTS).mkdir()
    with Session(job.engine) as db:
        for what in WHAT:
            frame = pseudonymous(export_table(db, job.config, job.study_id, what), what,
                                 job.with_free_text)
            target = staging / EXPORTS / f"{what}.csv"
            write_csv(frame, target)
            write_export_package(frame, job.config, job.study_id, what, target)


def write_preregistration(job: ArchiveJob, staging: Path) -> None:
    """prereg/: the study's preregistration (`tomstudy prereg`), Markdown and HTML."""
    write_prereg(job.settings, job.study_id, staging / PREREG)


def pseudonymous(frame: pd.DataFrame, what: str, with_free_text: bool) -> pd.DataFrame:
    """An export as an archive holds it: WITHHELD_COLUMNS dropped and, unless
    `with_free_text`, only the survey answers of CLOSED_KINDS questions."""
    frame = frame.drop(columns=WITHHELD_COLUMNS.get(what, []))
    if what == "survey" and not with_free_text:
        frame = frame[frame["kind"].isin(CLOSED_KINDS)].reset_index(drop=True)
    return frame


def write_environment(job: ArchiveJob, staging: Path) -> None:
    """environment.json: the lock of the machine that wrote the archive."""
    write_json(staging / ENVIRONMENT, environment())


def environment() -> dict:
    """Python's version, the platform and every installed distribution with its version (the
    first on sys.path of a name, which is the one imported)."""
    versions: dict[str, str] = {}
    for dist in importlib.metadata.distributions():
        name = dist.metadata["Name"]
        if name:
            versions.setdefault(name, dist.version)
    return {"python": sys.version, "implementation": platform.python_implementation(),
            "platform": platform.platform(), "machine": platform.machine(),
            "distributions": dict(sorted(versions.items(), key=lambda kv: kv[0].lower()))}


def write_analysis(job: ArchiveJob, staging: Path) -> None:
    """analysis/: `tomstudy analyze` of the staged exports with the staged config and bundle,
    its numbers (summary.json and every CSV) and report.html."""
    with tempfile.TemporaryDirectory(prefix="tomstudy-analysis-") as tmp:
        run_archived_analysis(staging, job.study_id, Path(tmp))
        (staging / ANALYSIS).mkdir()
        for path in sorted(Path(tmp).iterdir()):
            if path.name in ("summary.json", "report.html") or path.suffix == ".csv":
                shutil.copyfile(path, staging / ANALYSIS / path.name)


# Each writes its members into the staging folder, in this order (the analysis reads the
# bundle, the study config and the exports written before it).
MEMBER_WRITERS: tuple[Callable[[ArchiveJob, Path], None], ...] = (
    write_bundle,
    write_study_config,
    write_exports,
    write_analysis,
    write_preregistration,
    write_environment,
)


def run_archived_analysis(root: Path, study_id: str, out: Path) -> dict:
    """`analyze` of the exported predictions under `root` (an archive's members) with its
    study config and bundle, into `out`; the summary."""
    return analyze(load_csv(root / ANALYSIS_SOURCE), study_id, out,
                   archived_inputs(root, study_id), ANALYSIS_SOURCE)


def archived_inputs(root: Path, study_id: str) -> StudyInputs:
    """The analysis's inputs from an archive's study config and its bundle (verified)."""
    config = load_yaml_model(root / STUDY / f"{study_id}.yaml", StudyConfig)
    return bundle_inputs(config, open_bundle(root / BUNDLE))


def write_archive(job: ArchiveJob, out: Path) -> dict:
    """Stage every member, write ARCHIVE.json, zip them atomically into `out` and enter the
    archive in the data dir's registry; the registry entry (path, SHA-256, participants)."""
    read_registry(job.settings.layout)  # an unreadable registry stops us before any work
    with tempfile.TemporaryDirectory(prefix="tomstudy-archive-") as tmp:
        staging = Path(tmp)
        for write_member in MEMBER_WRITERS:
            write_member(job, staging)
        manifest = archive_manifest(job, staging)
        write_json(staging / ARCHIVE_MANIFEST, manifest)
        pack(staging, list(manifest["members"]), out)
    return record_archive(job.settings.layout, out, sha256_file(out), manifest)


def archive_manifest(job: ArchiveJob, staging: Path) -> dict:
    """ARCHIVE.json's content for the members staged so far."""
    members = {p.relative_to(staging).as_posix(): {"sha256": sha256_file(p),
                                                   "bytes": p.stat().st_size}
               for p in sorted(staging.rglob("*")) if p.is_file()}
    return {"format": FORMAT, "study_id": job.study_id,
            "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
            "package_version": __version__, "members": members,
            "participant_ids": held_participants(staging),
            "withheld_columns": WITHHELD_COLUMNS, "free_text_answers": job.with_free_text}


def held_participants(staging: Path) -> list[str]:
    """The public participant ids of every staged export, sorted."""
    held: set[str] = set()
    for what in WHAT:
        held.update(read_export(staging / EXPORTS / f"{what}.csv", what)["participant_id"])
    return sorted(held)


def pack(staging: Path, members: list[str], out: Path) -> None:
    """Zip ARCHIVE.json, then `members`, from `staging` into `out` (atomically)."""
    with atomic_path(out) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for name in [ARCHIVE_MANIFEST, *members]:
            zf.write(staging / name, name)
