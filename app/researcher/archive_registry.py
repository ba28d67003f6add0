"""The data dir's registry of the archives `tomstudy archive` wrote, so that withdrawing a
participant later names the archives holding them (the lab re-issues those).

<data dir>/archives/registry.json is a JSON list, oldest first, one entry per archive: its
path, SHA-256, study, creation time and the public participant ids it holds. It is rewritten
atomically on each archive; a withdrawal reads it before deleting anything, so an unreadable
registry stops the withdrawal (named) instead of hiding an archive.
"""

import json
from pathlib import Path

from app.core.files import write_json
from app.layout import Layout

ENTRY_KEYS = ("path", "sha256", "study_id", "created_at", "participant_ids")


class RegistryError(ValueError):
    """The registry file cannot be read as a list of archive entries; names the file."""


def read_registry(layout: Layout) -> list[dict]:
    """Every archive entry of the data dir (none without a registry file)."""
    path = layout.archive_registry()
    if not path.is_file():
        return []
    try:
        entries = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise RegistryError(f"{path}: unreadable archive registry ({err}); restore or repair "
                            "it, nothing was deleted") from None
    if not isinstance(entries, list) or not all(
            isinstance(e, dict) and set(ENTRY_KEYS) <= set(e) for e in entries):
        raise RegistryError(f"{path}: not a list of archive entries with "
                            f"{', '.join(ENTRY_KEYS)}; restore or repair it, nothing was deleted")
    return entries


def record_archive(layout: Layout, archive: Path, sha256: str, manifest: dict) -> dict:
    """Add an archive (its file, hash and the manifest's study, time and participants) to the
    registry; returns the entry. A rewritten archive at the same path replaces its entry."""
    entry = {"path": str(Path(archive).resolve()), "sha256": sha256,
             "study_id": manifest["study_id"], "created_at": manifest["created_at"],
             "participant_ids": list(manifest["participant_ids"])}
    kept = [e for e in read_registry(layout) if e["path"] != entry["path"]]
    write_json(layout.archive_registry(), [*kept, entry])
    return entry


def archives_holding(entries: list[dict], study_id: str, participant_ids: list[str]
                     ) -> list[dict]:
    """The archives of `study_id` among `entries` that hold any of `participant_ids`: path,
    SHA-256 and creation time of each, oldest first."""
    wanted = set(participant_ids)
    return [{"path": e["path"], "sha256": e["sha256"], "created_at": e["created_at"]}
            for e in entries
            if e["study_id"] == study_id and wanted.intersection(e["participant_ids"])]
