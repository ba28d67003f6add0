"""Run whatever a study still lacks, up to the frozen bundle it is served from.

A `shipped` study (the paper's) is served from the bundle in the configs dir as it is: a fresh
clone simulates and trains nothing. A `built` study's bundle is made once by `build_bundle`,
the steps `tomstudy bundle build` runs: simulate both worlds, train every seed of both models
(app/learning/family.py), build the bank and freeze it (app/bank/bundle.py), warning of
every checkpoint whose training hit its cap before converging. Each step is skipped when its
output exists (the bank also when it still matches its checkpoints), so an interrupted build
resumes. A bundle that exists is served as it is: rebuilding is explicit.
"""

import json
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from app.bank.bundle import MANIFEST, Bundle, bundle_dir, shipped_dir
from app.bank.freeze import freeze
from app.bank.training_report import cap_warning
from app.bank.verify import open_bundle
from app.core.files import sha256_file
from app.layout import Layout
from app.settings import Settings
from app.study.config import StudyConfig, bank_design, load_study_config


def prepare_study(settings: Settings, study_id: str, workers: int = 2,
                  say: Callable[[str], None] = print) -> Path:
    """The folder of the bundle `study_id` is served from, built first if it is a missing
    `built` one."""
    config = load_study_config(settings, study_id)
    root = bundle_dir(config, study_id, settings.configs_dir, settings.layout)
    if config.bundle == "shipped" or (root / MANIFEST).is_file():
        say(f"serving the {config.bundle} bundle {root}")
        return root
    return build_bundle(settings, study_id, workers, say=say).root


def build_bundle(settings: Settings, study_id: str, workers: int = 2, n_trajectories: int = 2000,
                 seed: int = 0, say: Callable[[str], None] = print) -> Bundle:
    """Simulate, train the model family and build the bank where missing or stale, then freeze
    the bundle into the data dir's bundles/<study>/ (never into the configs dir)."""
    from app.learning.config import load_train_config
    from app.learning.family import train_family
    from app.learning.jobs import JobPool
    from app.learning.select import ensure_selected

    started = time.perf_counter()
    phases: dict[str, float] = {}
    config = load_study_config(settings, study_id)
    layout = settings.layout
    with timed(phases, "data"):
        for world in config.worlds:
            ensure_trajectories(layout, world, n_trajectories, seed, say)
    with JobPool(workers) as pool:  # one set of workers for both phases: each start costs
        with timed(phases, "selection"):  # a torch import
            train_cfg = ensure_selected(layout, config.worlds, load_train_config(), say, pool)
        with timed(phases, "training"):
            train_family(layout, config.worlds, config.models.seeds, train_cfg, pool, say)
    with timed(phases, "bank"):
        if bank_is_current(layout, study_id, config):
            say(f"{layout.bank(study_id)} is up to date; skipping build-trials")
        else:
            from app.bank.build import build_trials

            say(f"building the trial bank of {study_id}")
            build_trials(config, study_id, layout)
    out = layout.bundle_dir(study_id)
    bundle = freeze(config, study_id, settings.configs_dir, layout, out,
                    round(time.perf_counter() - started, 1), phases)
    say(f"froze {out} ({len(bundle.manifest['files'])} files)")
    for row in bundle.manifest["unconverged"]:
        say(cap_warning(row, layout.model_dir(row["world"], row["model"], row["seed"])))
    return bundle


@contextmanager
def timed(phases: dict[str, float], name: str) -> Iterator[None]:
    """Add the block's wall time (s, rounded) to phases[name]."""
    started = time.perf_counter()
    try:
        yield
    finally:
        phases[name] = round(time.perf_counter() - started, 1)


def replace_shipped(built: Bundle, configs_dir: Path, study_id: str) -> Path:
    """Copy a built bundle over the one that ships in the configs dir; returns its folder
    once the copy opens as a bundle (maintainers commit it with the numbers it changes)."""
    shipped = shipped_dir(configs_dir, study_id)
    shutil.rmtree(shipped, ignore_errors=True)
    shutil.copytree(built.root, shipped)
    open_bundle(shipped)
    return shipped


def ensure_trajectories(layout: Layout, world: str, n: int, seed: int, say) -> None:
    """Simulate a world, or import a recorded one's recordings, unless its trajectory file
    exists."""
    npz_path = layout.trajectories(world)
    if npz_path.is_file() and layout.trajectories_meta(world).is_file():
        say(f"{npz_path} exists; skipping simulate")
        return
    from app.worlds.world_data import make_world_data

    make_world_data(world, layout, n, seed, say)


def bank_is_current(layout: Layout, study_id: str, config: StudyConfig) -> bool:
    """True if the study's working bank exists, was built with this config's bank design, and
    its checkpoints and trajectories (named relative to the data dir) are unchanged."""
    bank, meta_path = layout.bank(study_id), layout.bank_meta(study_id)
    if not bank.is_file() or not meta_path.is_file():
        return False
    meta = json.loads(meta_path.read_text())
    stored = bank_design(meta.get("config", {}))
    if stored is None or stored != bank_design(config.model_dump(mode="json")):
        return False
    for world in meta.get("worlds", {}).values():
        inputs = [(world["trajectories"], world["trajectories_sha256"])]
        inputs += [(c["path"], c["file_sha256"]) for c in world["checkpoints"].values()]
        for path, digest in inputs:
            if not layout.resolve(path).is_file() or sha256_file(layout.resolve(path)) != digest:
                return False
    return sha256_file(bank) == meta.get("bank_sha256")
