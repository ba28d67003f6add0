"""Typed training config for Ours and the VAE (study_configs/training.yaml)."""

from pathlib import Path

from pydantic import Field, model_validator

from app.configio import StrictModel, load_yaml_model
from app.settings import get_settings

MODELS = ("ours", "vae")


class WorldSelection(StrictModel):
    """Values `tomstudy select` chose for one world; unset keys keep the default."""

    levels: list[int] | None = Field(None, min_length=1)
    beta_kl: float | None = Field(None, ge=0)
    vae_latent_dim: int | None = Field(None, ge=1)


class TrainConfig(StrictModel):
    """Window shape, network sizes, optimiser and loss settings; defaults match the study."""

    segment_len: int = Field(5, ge=1)
    n_actions: int = Field(3, ge=1)
    levels: list[int] = Field(default_factory=lambda: [3, 3], min_length=1)
    fsq_noise_fraction: float = Field(0.5, ge=0, le=1)
    encoder_hidden: list[int] = Field(default_factory=lambda: [128, 128])
    decoder_hidden: list[int] = Field(default_factory=lambda: [128, 128])
    lr: float = Field(3e-3, gt=0)
    batch_size: int = Field(512, ge=1)
    # a cap well above the epochs these models need to converge (at most 136 measured on
    # simulated data): training stops on patience_epochs (app/learning/convergence.py)
    max_epochs: int = Field(400, ge=1)
    patience_epochs: int = Field(12, ge=1)
    beta_kl: float = Field(0.01, ge=0)
    vae_latent_dim: int = Field(2, ge=1)
    pred_weight: float = Field(1.0, ge=0)
    recon_weight: float = Field(1.0, ge=0)
    action_axis_weights: list[float] = Field(default_factory=lambda: [1.0, 1.0], min_length=2,
                                             max_length=2)
    windows_per_trajectory: int = Field(20, ge=1)
    split_seed: int = Field(0, ge=0)
    val_fraction: float = Field(0.15, gt=0, lt=1)
    test_fraction: float = Field(0.15, gt=0, lt=1)
    min_code_share: float = Field(0.01, ge=0, lt=1)
    # world name -> chosen values; train_and_save applies them on top of the keys above
    selected: dict[str, WorldSelection] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check(self) -> "TrainConfig":
        if any(level < 2 for level in self.levels):
            raise ValueError("levels: every channel needs at least 2 levels")
        if any(w <= 0 for w in self.action_axis_weights):
            raise ValueError("action_axis_weights: both weights must be > 0")
        if any(h < 1 for h in self.encoder_hidden + self.decoder_hidden):
            raise ValueError("encoder_hidden/decoder_hidden: sizes must be >= 1")
        if self.val_fraction + self.test_fraction >= 0.9:
            raise ValueError("val_fraction + test_fraction must leave at least 10% for training")
        return self

    def latent_dim(self, model_name: str) -> int:
        """Latent size of a model: one channel per FSQ level entry (Ours), vae_latent_dim (VAE)."""
        return len(self.levels) if model_name == "ours" else self.vae_latent_dim

    def for_world(self, world: str) -> "TrainConfig":
        """The config training uses for `world`: selected[world] applied, `selected` emptied."""
        chosen = self.selected.get(world)
        update = chosen.model_dump(exclude_none=True) if chosen else {}
        return type(self).model_validate({**self.model_dump(), **update, "selected": {}})


def default_train_config_path() -> Path:
    """study_configs/training.yaml under the configured configs dir."""
    return get_settings().configs_dir / "training.yaml"


def load_train_config(path: Path | None = None, overrides: dict | None = None) -> TrainConfig:
    """Read the training YAML (default study_configs/training.yaml); errors name the field."""
    path = Path(path) if path else default_train_config_path()
    if path == default_train_config_path() and not path.exists():
        return TrainConfig(**(overrides or {}))
    return load_yaml_model(path, TrainConfig, overrides)
