"""Freezing a study's bundle: its bank, checkpoints, data meta and configs, with a manifest.

The manifest lists every file's SHA-256 and size, the bank's hash, each checkpoint's content
hash, the checkpoints whose training hit its cap unconverged, and where and how the bundle
was built; gzip files carry no name or time, so equal content gives equal bytes.
"""

import json
import os
import platform
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

import app
from app.bank.bundle import (
    BANK,
    BANK_META,
    FORMAT,
    MANIFEST,
    MODELS,
    SHARED_CONFIGS,
    Bundle,
    checkpoint_file,
    metrics_file,
)
from app.bank.training_report import checkpoint_stopping, unconverged
from app.bank.verify import open_bundle
from app.core.contracts import COARSE_OBSERVERS
from app.core.files import sha256_bytes, sha256_file, write_gzip, write_json
from app.layout import Layout
from app.predictors.registry import distribution
from app.study.config import StudyConfig
from app.study.trials import TrialBank


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
    files.update(build_selections(config, configs_dir, layout))
    files[f"configs/{study_id}.yaml"] = (configs_dir / f"{study_id}.yaml").read_bytes()
    for name in SHARED_CONFIGS:
        if (configs_dir / name).is_file():
            files[f"configs/{name}"] = (configs_dir / name).read_bytes()
    return files


def build_selections(config: StudyConfig, configs_dir: Path, layout: Layout) -> dict[str, bytes]:
    """selection/<world>.json of every world whose sizes the build chose (training.yaml selects
    nothing for it; app/learning/select.py ensure_selected), so the bundle says why its
    checkpoints have the levels, beta and latent size they have."""
    from app.learning.config import load_train_config

    selected = load_train_config(Path(configs_dir) / "training.yaml").selected
    found = {world: layout.selection_dir(world) / "selection.json" for world in config.worlds
             if world not in selected}
    return {f"selection/{world}.json": path.read_bytes() for world, path in found.items()
            if path.is_file()}


def freeze(config: StudyConfig, study_id: str, configs_dir: Path, layout: Layout,
           out: Path, wall_time_s: float | None = None,
           phases: dict[str, float] | None = None) -> Bundle:
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
    record = manifest(config, study_id, bank, entries, wall_time_s, phases)
    record["unconverged"] = unconverged(checkpoint_stopping(staging, record["models"]))
    write_json(staging / MANIFEST, record)
    shutil.rmtree(out, ignore_errors=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    os.replace(staging, out)
    return open_bundle(out)


def manifest(config: StudyConfig, study_id: str, bank: TrialBank, entries: dict,
             wall_time_s: float | None, phases: dict[str, float] | None = None) -> dict:
    """The manifest: the files, what the bank answers with (checkpoints, coarse observers and
    plug-ins), and where it was built."""
    models = {world: {model: {str(a.seed): a.content_hash
                              for a in bank.trials_of(world, "main")[0].predictions[model]}
                      for model in MODELS}
              for world in bank.data.worlds}
    out = {"format": FORMAT, "study_id": study_id, "bank_sha256": bank.sha256,
           "seeds": list(config.models.seeds), "models": models,
           "content_sha256": sha256_bytes(json.dumps(entries, sort_keys=True).encode()),
           "files": entries, "built": build_environment(wall_time_s, phases)}
    plugins = plugin_entries(bank)
    if plugins:
        out["predictors"] = plugins
    observers = observer_entries(bank)
    if observers:
        out["observers"] = observers
    return out


def observer_entries(bank: TrialBank) -> dict[str, str]:
    """Each coarse observer the bank stores answers of: its content hash (the observer
    parameters' values it answered under; the bundle's observers.yaml holds them)."""
    first = next(iter(bank.by_id.values()))
    return {name: first.predictions[name][0].content_hash for name in COARSE_OBSERVERS
            if name in first.predictions}


def plugin_entries(bank: TrialBank) -> dict:
    """Each plug-in predictor the bank stores answers of: its content hash (as stored) and the
    installed distribution and version that provide it."""
    first = next(iter(bank.by_id.values()))
    return {name: {"content_hash": family[0].content_hash, **distribution(name)}
            for name, family in sorted(first.predictions.items())
            if name not in MODELS and name not in COARSE_OBSERVERS}


def build_environment(wall_time_s: float | None, phases: dict[str, float] | None = None) -> dict:
    """Where and with what a bundle was built (informational: not part of its content hash)."""
    import torch

    return {"package_version": app.__version__, "git_commit": git_commit(),
            "python": platform.python_version(), "numpy": np.__version__,
            "torch": torch.__version__, "machine": platform.machine(),
            "platform": platform.platform(), "cpus": os.cpu_count(),
            "built_at_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "wall_time_s": wall_time_s, **({"phase_wall_time_s": phases} if phases else {})}


def git_commit() -> str:
    """The commit of the code that built the bundle ('' outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).resolve().parent, timeout=10, check=False)
    except OSError:
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""
