"""Typed training config for Ours and the VAE (study_configs/training.yaml)."""

from pathlib import Path

from pydantic import Field, model_validator

from app.configio import StrictModel, load_yaml_model
from app.settings import get_settings

MODELS = ("ours", "vae")


class WorldSelection(StrictModel):
    """Values `tomstudy select` chose for one world; unset keys keep the default."""

    # Ours' FSQ levels chosen for this world (None: the top-level `levels`)
    levels: list[int] | None = Field(None, min_length=1)
    # the VAE's KL weight chosen for this world (None: the top-level `beta_kl`)
    beta_kl: float | None = Field(None, ge=0)
    # the VAE's latent size chosen for this world (None: the top-level `vae_latent_dim`)
    vae_latent_dim: int | None = Field(None, ge=1)


class TrainConfig(StrictModel):
    """Window shape, network sizes, optimiser and loss settings; defaults match the study."""

    # observed steps (>= 1) the models read before they predict: the length of a training window's
    # segment and the history a model needs
    segment_len: int = Field(5, ge=1)
    # future robot moves (>= 1) a model predicts after the segment
    n_actions: int = Field(3, ge=1)
    # Ours' FSQ levels, one entry (>= 2) per latent channel: the codebook has their product codes
    levels: list[int] = Field(default_factory=lambda: [3, 3], min_length=1)
    # share (0-1) of Ours' quantised entries replaced by one-bin uniform noise in training (0: plain
    # straight-through rounding, the paper's quantiser)
    fsq_noise_fraction: float = Field(0.5, ge=0, le=1)
    # widths of the encoder's hidden layers (each >= 1), Ours and the VAE alike
    encoder_hidden: list[int] = Field(default_factory=lambda: [128, 128])
    # widths of the decoder's hidden layers (each >= 1)
    decoder_hidden: list[int] = Field(default_factory=lambda: [128, 128])
    # the optimiser's learning rate (> 0)
    lr: float = Field(3e-3, gt=0)
    # training windows (>= 1) per gradient step
    batch_size: int = Field(512, ge=1)
    # a cap well above the epochs these models need to converge (at most 136 measured on
    # simulated data): training stops on patience_epochs (app/learning/convergence.py)
    max_epochs: int = Field(400, ge=1)
    # epochs (>= 1) without a better validation loss after which training stops and keeps the best
    # epoch
    patience_epochs: int = Field(12, ge=1)
    # the VAE's KL term weight (>= 0); larger pushes its latent towards the prior
    beta_kl: float = Field(0.01, ge=0)
    # the VAE's latent size (>= 1)
    vae_latent_dim: int = Field(2, ge=1)
    # weight (>= 0) of the prediction loss (MSE of the future moves) in the training and selection
    # loss
    pred_weight: float = Field(1.0, ge=0)
    # weight (>= 0) of the reconstruction loss (MSE of the segment's moves)
    recon_weight: float = Field(1.0, ge=0)
    # weights (> 0) of the two action axes in the normalised MSE: w scales that axis' error by w
    action_axis_weights: list[float] = Field(default_factory=lambda: [1.0, 1.0], min_length=2,
                                             max_length=2)
    # evenly spaced training windows (>= 1) cut from each trajectory
    windows_per_trajectory: int = Field(20, ge=1)
    # seed (>= 0) of the train / validation / test split by trajectory
    split_seed: int = Field(0, ge=0)
    # share (0-1) of trajectories in the validation split (early stopping, model selection)
    val_fraction: float = Field(0.15, gt=0, lt=1)
    # share (0-1) of trajectories in the test split (reported only); val + test must leave at least
    # 10 % for training
    test_fraction: float = Field(0.15, gt=0, lt=1)
    # share [0, 1) of windows a code must hold to count as used in the code-usage metrics
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
