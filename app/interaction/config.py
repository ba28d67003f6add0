"""The INTERACTION experiment's settings: how pairs are cut, scored and what is reported."""

from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator

from app.configio import StrictModel, omitted_when_default
from app.recordings.tracks import FRAME_MS


class SecondaryConfig(StrictModel):
    """The secondary analyses, fixed before they are run (study_configs/interaction.yaml)."""

    horizons_s: list[float] = Field([1.0, 2.0, 3.0], min_length=1,
                                    description="displacement horizons after the 1 s observed")
    decision_heading_deg: float = Field(30.0, gt=0, description="a turn within the horizon "
                                        "larger than this makes a decision moment")
    windows_per_pair: int = Field(10, ge=1, description="val windows per pair and horizon")
    v10_window_frames: int = Field(42, ge=8, description="v1.0 val pairs for the horizons: "
                                   "1 s + 3 s at 0.2 s steps needs 41 frames")
    alpha: float = Field(0.05, gt=0, lt=1, description="family-wise, Holm-corrected")


class CodeLevelsConfig(StrictModel):
    """Ours' FSQ levels grid and the rule that picks one cell on validation loss alone
    (the rule of study_configs/model_selection.yaml), fixed before any purity is computed."""

    levels: list[list[int]] = Field([[2, 2], [2, 2, 2], [3, 3], [4, 4], [5, 3], [3, 3, 3],
                                     [5, 5]], min_length=1,
                                    description="the FSQ levels lists tried, one Ours training "
                                    "each; the rule picks the one every seed trains with")
    min_used_fraction: float = Field(0.5, ge=0, le=1, description="eligible: used codes at "
                                     "least this share of the codebook")
    loss_tolerance: float = Field(0.05, ge=0, description="relative; of the cells this close "
                                  "to the lowest eligible loss, the fewest used codes")
    seed: int = Field(0, ge=0, description="the training seed of every levels cell")


class FrameSensitivityConfig(StrictModel):
    """The sensitivity row: the paper's protocol re-run with the models' positions in another
    frame than the primary's map frame (app/interaction/frames.py)."""

    frame: Literal["human_relative"] = Field("human_relative", description="positions minus "
                                             "the human car's at the last observed step")
    seeds: int = Field(5, ge=0, description="seeds 0..k-1 of the primary's; 0 = not run")

    @field_validator("seeds")
    @classmethod
    def _none_or_a_pair(cls, seeds: int) -> int:
        if seeds == 1:
            raise ValueError("a paired t-test over seeds needs at least 2 (0 skips the row)")
        return seeds


class InteractionConfig(StrictModel):
    """How pairs are cut and scored; defaults follow the paper (1 s observed, 10 seeds)."""

    window_frames: int = Field(40, ge=8, description="frames per pair window (4 s at 10 Hz)")
    window_stride_frames: int = Field(40, ge=1, description="v1.0: step between windows")
    observed_frames: int = Field(10, ge=2, description="observed segment: 10 intervals = 1 s")
    downsample: int = Field(2, ge=1, description="keep every k-th frame (k=2: dt 0.2 s)")
    predict_steps: int = Field(3, ge=1, description="n actions predicted (ADE/FDE horizon)")
    pair_max_distance_m: float = Field(30.0, gt=0, description="a robot/human pair is kept "
                                       "when they come this close (m) in the window")
    min_speed_mps: float = Field(0.5, ge=0, description="true next speed needed to score")
    turn_threshold_deg: float = Field(30.0, gt=0, description="heading change = a turn")
    v10_train_fraction: float = Field(0.8, gt=0, lt=1,
                                      description="v1.0 time split without a devkit val list")
    v10_validation_list: Literal["use", "ignore"] = Field(
        "use", description="v1.0: hold out the devkit's validation list's recordings ('use'), "
        "or ignore the list and split every recording in time ('ignore')")
    seeds: int = Field(10, ge=2, description="training seeds 0..k-1 (>= 2) of Ours and the "
                       "VAE in the primary protocol; --seeds overrides it")
    max_train_pairs: int = Field(700, ge=0, description="an even subsample beyond this "
                                 "(fixed from the time budget); 0 = every pair")
    eval_windows_per_pair: int = Field(20, ge=1, description="evenly spaced windows scored "
                                       "per val pair")
    field_grid: int = Field(25, ge=5, description="grid points per side of a vector field")
    field_codes: int = Field(6, ge=1, description="most used codes drawn per model")
    secondary: SecondaryConfig = Field(default_factory=SecondaryConfig,
                                       description="the secondary analyses")
    code_levels: CodeLevelsConfig = Field(default_factory=CodeLevelsConfig,
                                          description="how Ours' FSQ levels are chosen")
    frame_sensitivity: FrameSensitivityConfig = Field(default_factory=FrameSensitivityConfig,
                                                      description="the other-frame sensitivity "
                                                      "row")
    _without_new_keys = omitted_when_default("v10_validation_list")

    @property
    def segment_len(self) -> int:
        """Observed steps after downsampling."""
        return self.observed_frames // self.downsample

    @property
    def dt_s(self) -> float:
        """Step of the downsampled pairs."""
        return FRAME_MS / 1000 * self.downsample


def default_config_path() -> Path:
    """study_configs/interaction.yaml under the configured configs dir."""
    from app.settings import get_settings

    return get_settings().configs_dir / "interaction.yaml"


def load_config(path: Path | None, seeds: int | None,
                frame_seeds: int | None = None) -> InteractionConfig:
    """The experiment config (default study_configs/interaction.yaml), then --seeds and
    --frame-seeds."""
    from app.configio import load_yaml_model

    overrides = {"seeds": seeds} if seeds is not None else {}
    path = Path(path) if path else default_config_path()
    if not path.exists() and path == default_config_path():
        cfg = InteractionConfig(**overrides)
    else:
        cfg = load_yaml_model(path, InteractionConfig, overrides)
    if frame_seeds is None:
        return cfg
    row = FrameSensitivityConfig(**{**cfg.frame_sensitivity.model_dump(), "seeds": frame_seeds})
    return cfg.model_copy(update={"frame_sensitivity": row})
