"""Where a bundle is verified before anything is served from it.

Opening a bundle checks every file against its manifest (a missing, altered or unlisted file
is refused, named) and the bank's hash; loading a study's bundle also checks that the live
study config shapes the bank as the frozen one did. That the checkpoints still give the
answers the bank stores is the third check, app/bank/model_answers.py's `recompute`, which
the server runs at start-up and `tomstudy bundle verify` prints.
"""

import json
from pathlib import Path

import yaml

from app.bank.bundle import BANK, FORMAT, MANIFEST, Bundle, BundleError, bundle_dir
from app.core.files import sha256_file
from app.layout import Layout
from app.study.config import StudyConfig, bank_design
from app.study.trials import TrialBank


def open_bundle(root: Path) -> Bundle:
    """Open a bundle: every file checked against its manifest (BundleError names the first
    missing, altered or unlisted one)."""
    root = Path(root)
    manifest = verified_manifest(root)
    bank = TrialBank.read(root / BANK)
    if bank.sha256 != manifest["bank_sha256"]:
        raise BundleError(f"{root / BANK}: the bank's JSON hashes to {bank.sha256[:12]}, the "
                          f"manifest says {manifest['bank_sha256'][:12]}")
    return Bundle(root, manifest, bank)


def verified_manifest(root: Path) -> dict:
    """The manifest of the bundle at `root`, once every file matches it."""
    path = root / MANIFEST
    if not path.is_file():
        raise BundleError(f"{root}: no bundle here ({MANIFEST} missing)")
    manifest = json.loads(path.read_text())
    if manifest.get("format") != FORMAT:
        raise BundleError(f"{path}: not a {FORMAT} manifest")
    listed = manifest["files"]
    for name, entry in sorted(listed.items()):
        file = root / name
        if not file.is_file():
            raise BundleError(f"{file}: listed in the manifest but missing")
        if sha256_file(file) != entry["sha256"]:
            raise BundleError(f"{file}: altered (its SHA-256 is not the manifest's)")
    present = {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}
    unlisted = sorted(present - set(listed) - {MANIFEST})
    if unlisted:
        raise BundleError(f"{root / unlisted[0]}: not in the manifest ({len(unlisted)} such "
                          "file(s)); a bundle holds exactly what its manifest lists")
    return manifest


def check_design(bundle: Bundle, config: StudyConfig, config_path: Path) -> None:
    """BundleError unless the live study config shapes the bank as the bundle's config did
    (texts, recruitment and scoring may change; trials, models and seeds may not)."""
    live_keys = config.model_dump(mode="json")
    # an older bundle's config may lack keys this version added (a new screen's text): the
    # live config fills only those, so what the frozen file says is what is compared
    written = yaml.safe_load((bundle.root / "configs" / f"{bundle.study_id}.yaml").read_text())
    frozen = bank_design(live_keys | written) or {}
    live = bank_design(live_keys)
    changed = sorted(key for key in live if frozen.get(key) != live[key])
    if changed:
        raise BundleError(f"{config_path}: differs from the bundle's config ({bundle.root}) in "
                          f"what shapes the trial bank: {', '.join(changed)}; restore those keys "
                          f"or rebuild the bundle (`tomstudy bundle build --study "
                          f"{bundle.study_id}`)")


def load_bundle(config: StudyConfig, study_id: str, configs_dir: Path, layout: Layout) -> Bundle:
    """The verified bundle a study's config names, whose bank design matches that config."""
    root = bundle_dir(config, study_id, configs_dir, layout)
    if not (root / MANIFEST).is_file():
        how = ("it ships with the code: restore it from git" if config.bundle == "shipped"
               else f"build it with `tomstudy bundle build --study {study_id}`")
        raise BundleError(f"{root}: no bundle of study {study_id}; {how}")
    bundle = open_bundle(root)
    if bundle.study_id != study_id:
        raise BundleError(f"{root}: the bundle is of study {bundle.study_id!r}, not {study_id!r}")
    check_design(bundle, config, Path(configs_dir) / f"{study_id}.yaml")
    return bundle
