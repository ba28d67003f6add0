"""What the offline commands read of the bundle a study is served from.

`analyze`, `power`, `instrument`, `pilot` and `check-display` work on the bank the
participants see: the one in the study's bundle (app/bank/bundle.py), never the data dir's
working bank. This module says which files that is, and what each command takes from them.
"""

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from app.bank.bundle import BANK, Bundle, BundleError
from app.bank.verify import load_bundle
from app.core.contracts import StudyInputs
from app.settings import Settings
from app.study.config import StudyConfig, load_study_config

if TYPE_CHECKING:
    from app.observers.config import ObserversConfig


def served_bundle(settings: Settings, study_id: str) -> Bundle:
    """The verified bundle `study_id` is served from (BundleError if it cannot be)."""
    config = load_study_config(settings, study_id)
    return load_bundle(config, study_id, settings.configs_dir, settings.layout)


def served_bank(settings: Settings, study_id: str) -> Path:
    """The trial bank file of the bundle `study_id` is served from."""
    return served_bundle(settings, study_id).root / BANK


def analysis_inputs(settings: Settings, study_id: str,
                    warn: Callable[[str], None] = print) -> StudyInputs:
    """What `analyze` takes from the study config and its bundle, as plain values and paths
    (without a bundle on this machine the analysis runs on the export alone, and `warn`s)."""
    config = load_study_config(settings, study_id)
    try:
        bundle = load_bundle(config, study_id, settings.configs_dir, settings.layout)
    except BundleError as err:
        warn(f"{err}; per-seed and family results need the bundle")
        return study_inputs(config, {}, settings.layout.bundle_dir(study_id) / BANK)
    return bundle_inputs(config, bundle)


def bundle_inputs(config: StudyConfig, bundle: Bundle) -> StudyInputs:
    """What `analyze` takes from a study config and the verified bundle it is served from."""
    return study_inputs(config, bundle.manifest["models"], bundle.root / BANK)


def study_inputs(config: StudyConfig, models: dict, bank: Path) -> StudyInputs:
    """The analysis's inputs as plain values and paths: the config, its exclusion rules, the
    model family's content hashes and the trial bank's file."""

    return StudyInputs(config=config.model_dump(mode="json"), rules=config.exclusions,
                       models=models, bank=bank)


@dataclass(frozen=True)
class SimulationInputs:
    """What simulated participants of a study run on."""

    bank: Path
    observers: "ObserversConfig"
    trials_per_world: int


def simulation_inputs(settings: Settings, study_id: str, observers: Path | None = None,
                      bank: Path | None = None) -> SimulationInputs:
    """The served bank (unless `bank` names another), the observers config (`observers`, or
    the configs dir's) and the study's trials per world; BundleError or ConfigError."""
    from app.observers.config import default_observers, load_observers

    bank = bank or served_bank(settings, study_id)
    config = load_observers(observers) if observers else default_observers(settings.configs_dir)
    trials = load_study_config(settings, study_id).trials_per_world
    return SimulationInputs(bank, config, trials)
