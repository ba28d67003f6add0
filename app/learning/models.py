"""The two networks by name: build Ours or the VAE from the architecture a checkpoint stores.

Training builds a fresh network here and a loaded checkpoint rebuilds its torch module here,
so neither train.py nor checkpoint.py needs the other to construct a model.
"""

from app.learning.config import MODELS, TrainConfig
from app.learning.networks import LatentActionModel
from app.learning.ours import OursModel
from app.learning.vae import VAEModel


def build_model(model_name: str, args: dict) -> LatentActionModel:
    """Construct the torch network `model_name` (ours or vae) from plain model args."""
    common = dict(segment_len=args["segment_len"], n_actions=args["n_actions"],
                  encoder_hidden=list(args["encoder_hidden"]),
                  decoder_hidden=list(args["decoder_hidden"]))
    if model_name == "ours":
        # checkpoints written before the option existed trained without noise
        return OursModel(levels=list(args["levels"]),
                         fsq_noise_fraction=float(args.get("fsq_noise_fraction", 0.0)), **common)
    if model_name == "vae":
        return VAEModel(latent_dim=args["latent_dim"], beta_kl=args["beta_kl"], **common)
    raise ValueError(f"unknown model {model_name!r}; choose one of {', '.join(MODELS)}")


def model_args(cfg: TrainConfig, model_name: str) -> dict:
    """The architecture part of the config, stored in the checkpoint."""
    return {"segment_len": cfg.segment_len, "n_actions": cfg.n_actions, "levels": cfg.levels,
            "latent_dim": cfg.latent_dim(model_name), "encoder_hidden": cfg.encoder_hidden,
            "decoder_hidden": cfg.decoder_hidden, "beta_kl": cfg.beta_kl,
            "fsq_noise_fraction": cfg.fsq_noise_fraction}
