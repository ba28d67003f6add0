"""A study's frozen bundle: the one thing a server serves and a preregistration can name.

    <bundle>/manifest.json                         format, SHA-256 and size of every other file,
                                                   the bank's hash, every checkpoint's content
                                                   hash, and where and how it was built
    <bundle>/bank.json.gz                          the trial bank (app/study/trials.py)
    <bundle>/bank_meta.json                        how the bank was built (its meta.json)
    <bundle>/models/<world>/<model>/seed<k>.pt.gz  every checkpoint whose answers the bank stores
    <bundle>/models/<world>/<model>/seed<k>.metrics.json.gz   its training and test figures
    <bundle>/data/<world>.meta.json                how the trajectories were simulated (hashes)
    <bundle>/configs/...                           the study, training, selection, observer and
                                                   world configs that made it

A study config's `bundle` says where its bundle is: `shipped` (<configs dir>/bundles/<study>/,
in git, so every machine serves the same study) or `built` (<data dir>/bundles/<study>/, made
by `tomstudy bundle build`). Opening a bundle checks every file against the manifest and
refuses a missing, altered or unlisted one. The gzip files carry no name or time, so equal
content gives equal bytes.
"""

import json
import os
import platform
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

import app
from analysis.atomic import write_json
from app.configio import load_yaml_model
from app.fileio import sha256_bytes, sha256_file, write_gzip
from app.layout import Layout
from app.study.config import StudyConfig, bank_design
from app.study.trials import TrialBank

FORMAT = "tomstudy-bundle-v1"
MANIFEST = "manifest.json"
BANK = "bank.json.gz"
BANK_META = "bank_meta.json"
MODELS = ("ours", "vae")
SHARED_CONFIGS = ("training.yaml", "model_selection.yaml", "observers.yaml")
BUNDLES = "bundles"  # the folder of shipped bundles in the configs dir


class BundleError(RuntimeError):
    """A bundle is missing, altered, or does not belong to the study config that names it."""


def checkpoint_file(world: str, model: str, seed: int) -> str:
    """A checkpoint's path inside a bundle."""
    return f"models/{world}/{model}/seed{seed}.pt.gz"


def metrics_file(world: str, model: str, seed: int) -> str:
    """A checkpoint's metrics.json (training history, test figures) inside a bundle."""
    return f"models/{world}/{model}/seed{seed}.metrics.json.gz"


def shipped_dir(configs_dir: Path, study_id: str) -> Path:
    """<configs dir>/bundles/<study>/: where a study's bundle ships with the code."""
    return Path(configs_dir) / BUNDLES / study_id


def bundle_dir(config: StudyConfig, study_id: str, configs_dir: Path, layout: Layout) -> Path:
    """Where the study's config says its bundle is (shipped or built)."""
    if config.bundle == "shipped":
        return shipped_dir(configs_dir, study_id)
    return layout.bundle_dir(study_id)


@dataclass
class Bundle:
    """An opened, verified bundle: its manifest, its bank and its checkpoints (loaded lazily)."""

    root: Path
    manifest: dict
    bank: TrialBank
    _models: dict = field(default_factory=dict, repr=False)

    @property
    def study_id(self) -> str:
        """The study the bundle was built for."""
        return self.manifest["study_id"]

    @property
    def seeds(self) -> list[int]:
        """The model family's seeds, the primary first."""
        return list(self.manifest["seeds"])

    def study_config(self) -> StudyConfig:
        """The study config the bundle was built from (its configs/<study>.yaml)."""
        return load_yaml_model(self.root / "configs" / f"{self.study_id}.yaml", StudyConfig)

    def model(self, world: str, model: str, seed: int):
        """One checkpoint of the bundle as a TrainedModel (loaded once)."""
        from app.learning.checkpoint import load_model

        key = (world, model, seed)
        if key not in self._models:
            self._models[key] = load_model(self.root / checkpoint_file(*key), world=world)
        return self._models[key]


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


# ---------------------------------------------------------------- freezing

def bundle_files(config: StudyConfig, study_id: str, configs_dir: Path,
                 layout: Layout) -> dict[str, bytes]:
    """Every file of the study's bundle (name -> bytes), from the data dir's working bank,
    checkpoints and trajectories' meta and the configs dir."""
    configs_dir = Path(configs_dir)
    files = {BANK: layout.bank(study_id).read_bytes(),
             BANK_META: layout.bank_meta(study_id).read_bytes()}
    for world in config.worlds:
        files[f"data/{world}.meta.json"] = layout.trajectories_meta(world).read_bytes()
        files[f"configs/worlds/{world}.yaml"] = (configs_dir / "worlds" / f"{world}.yaml"
                                                 ).read_bytes()
        for model in MODELS:
            for seed in config.models.seeds:
                directory = layout.model_dir(world, model, seed)
                files[checkpoint_file(world, model, seed)] = (
                    layout.checkpoint(world, model, seed).read_bytes())
                files[metrics_file(world, model, seed)] = (directory / "metrics.json").read_bytes()
    files[f"configs/{study_id}.yaml"] = (configs_dir / f"{study_id}.yaml").read_bytes()
    for name in SHARED_CONFIGS:
        if (configs_dir / name).is_file():
            files[f"configs/{name}"] = (configs_dir / name).read_bytes()
    return files


def freeze(config: StudyConfig, study_id: str, configs_dir: Path, layout: Layout,
           out: Path, wall_time_s: float | None = None) -> Bundle:
    """Write the study's bundle to `out` (replacing what is there) and open it."""
    out = Path(out)
    staging = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    shutil.rmtree(staging, ignore_errors=True)
    entries = {}
    for name, data in sorted(bundle_files(config, study_id, configs_dir, layout).items()):
        target = staging / name
        if name.endswith(".gz"):
            write_gzip(target, data)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        entries[name] = {"sha256": sha256_file(target), "bytes": target.stat().st_size}
    bank = TrialBank.read(staging / BANK)
    write_json(staging / MANIFEST, manifest(config, study_id, bank, entries, wall_time_s))
    shutil.rmtree(out, ignore_errors=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    os.replace(staging, out)
    return open_bundle(out)


def manifest(config: StudyConfig, study_id: str, bank: TrialBank, entries: dict,
             wall_time_s: float | None) -> dict:
    """The manifest: the files, what the bank answers with, and where it was built."""
    models = {world: {model: {str(a.seed): a.content_hash
                              for a in bank.trials_of(world, "main")[0].predictions[model]}
                      for model in MODELS}
              for world in bank.data.worlds}
    return {"format": FORMAT, "study_id": study_id, "bank_sha256": bank.sha256,
            "seeds": list(config.models.seeds), "models": models,
            "content_sha256": sha256_bytes(json.dumps(entries, sort_keys=True).encode()),
            "files": entries, "built": build_environment(wall_time_s)}


def build_environment(wall_time_s: float | None) -> dict:
    """Where and with what a bundle was built (informational: not part of its content hash)."""
    import torch

    return {"package_version": app.__version__, "git_commit": git_commit(),
            "python": platform.python_version(), "numpy": np.__version__,
            "torch": torch.__version__, "machine": platform.machine(),
            "platform": platform.platform(), "cpus": os.cpu_count(),
            "built_at_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "wall_time_s": wall_time_s}


def git_commit() -> str:
    """The commit of the code that built the bundle ('' outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=10, check=False)
    except OSError:
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""
