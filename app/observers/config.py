"""The simulated observers' parameters (study_configs/observers.yaml), each with its source.

Every number is a `{value, source}` pair so a value cannot be added without saying where
it comes from; a misspelt key is an error that names it (app.configio.StrictModel).
"""

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field

from app.configio import StrictModel, load_yaml_model

OBSERVERS_FILE = "observers.yaml"


class _WithSource(StrictModel):
    """A config value (declared by the subclass) and where it comes from."""

    source: str = Field(min_length=8)


class Sourced(_WithSource):
    """A non-negative number and where it comes from."""

    value: float = Field(ge=0)


class PositiveSourced(Sourced):
    """A positive number and where it comes from."""

    value: float = Field(gt=0)


class UnitSourced(Sourced):
    """A share in [0, 1] and where it comes from."""

    value: float = Field(ge=0, le=1)


class IntentChoice(_WithSource):
    """How an observer turns its posterior into one intent: sample it, or take its mode."""

    value: Literal["sample", "map"]


class LaneReading(_WithSource):
    """What a Highway intent is: an absolute lane, or a lane change relative to the robot's lane."""

    value: Literal["absolute", "relative"]


class InferenceConfig(StrictModel):
    """Inverse planning: Boltzmann likelihood per observed step, Dirichlet prior from examples."""

    beta: Sourced
    prior_pseudo_count: PositiveSourced
    intent_choice: IntentChoice
    lane_reading: LaneReading


class NoiseConfig(StrictModel):
    """Perceptual noise: a Weber fraction on speed (per trial) and a direction SD (per click)."""

    speed_weber_fraction: Sourced
    direction_sd_deg: Sourced


class ObserversConfig(StrictModel):
    """All observer presets' parameters."""

    lane_change_duration_s: PositiveSourced
    momentum_weight: UnitSourced  # coarse_momentum: the intent's weight against motion seen
    inference: InferenceConfig
    coarse_noise: NoiseConfig
    precise_noise: NoiseConfig
    click_sd_px: PositiveSourced  # a click's spread on screen: the instrument's "view" noise


def load_observers(path: Path) -> ObserversConfig:
    """Read an observers YAML file; ConfigError names the file and any bad key."""
    return load_yaml_model(Path(path), ObserversConfig)


def default_observers(configs_dir: Path | None = None) -> ObserversConfig:
    """The observers config of a configs dir (default: the settings' study_configs)."""
    if configs_dir is None:
        from app.settings import get_settings

        configs_dir = get_settings().configs_dir
    return _cached(Path(configs_dir).resolve() / OBSERVERS_FILE)


@lru_cache(maxsize=8)
def _cached(path: Path) -> ObserversConfig:
    return load_observers(path)
