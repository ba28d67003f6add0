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

    source: str = Field(min_length=8, description="where the value comes from: the "
                        "publication or reasoning that fixed it (at least 8 characters)")


class Sourced(_WithSource):
    """A non-negative number and where it comes from."""

    # the number (>= 0), in the unit its key names
    value: float = Field(ge=0)


class PositiveSourced(Sourced):
    """A positive number and where it comes from."""

    # the number (> 0), in the unit its key names
    value: float = Field(gt=0)


class UnitSourced(Sourced):
    """A share in [0, 1] and where it comes from."""

    # the share, 0 to 1
    value: float = Field(ge=0, le=1)


class IntentChoice(_WithSource):
    """How an observer turns its posterior into one intent: sample it, or take its mode."""

    # `sample`: draw one intent from the posterior (probability matching); `map`: take the most
    # probable intent
    value: Literal["sample", "map"]


class LaneReading(_WithSource):
    """What a Highway intent is: an absolute lane, or a lane change relative to the robot's lane."""

    # `absolute`: an intent is the target lane; `relative`: a lane change (left, keep, right) from
    # the robot's start lane
    value: Literal["absolute", "relative"]


class InferenceConfig(StrictModel):
    """Inverse planning: Boltzmann likelihood per observed step, Dirichlet prior from examples."""

    # rationality (>= 0) of the Boltzmann likelihood exp(beta x progress) of an observed step;
    # larger trusts each step more
    beta: Sourced
    # pseudo-count (> 0) of the Dirichlet prior over intents that the example clips' outcomes
    # update; larger weighs the examples less
    prior_pseudo_count: PositiveSourced
    # how an observer turns its posterior into the one intent it acts on
    intent_choice: IntentChoice
    # what a Highway intent means to the observer
    lane_reading: LaneReading


class NoiseConfig(StrictModel):
    """Perceptual noise: a Weber fraction on speed (per trial) and a direction SD (per click)."""

    # SD (>= 0) of the perceived speed's relative error, drawn once per trial (0.1 = 10 %)
    speed_weber_fraction: Sourced
    # SD (degrees, >= 0) of the perceived direction's error, drawn per click
    direction_sd_deg: Sourced


class ObserversConfig(StrictModel):
    """All observer presets' parameters."""

    # Highway: seconds (> 0) a coarse observer expects a lane change to take; its lateral speed is
    # the lane width over this
    lane_change_duration_s: PositiveSourced
    momentum_weight: UnitSourced  # coarse_momentum: the intent's weight against motion seen
    # how an observer infers the robot's intent from what it saw
    inference: InferenceConfig
    # perceptual noise of the coarse (typical) observers
    coarse_noise: NoiseConfig
    # perceptual noise of the precise (best-case) observer
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
