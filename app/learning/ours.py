"""Ours: MLP encoder -> FSQ (discrete high-level behaviour z) -> MLP decoder (z, s) -> actions."""

import torch

from app.learning.fsq import FSQ
from app.learning.networks import LatentActionModel


class OursModel(LatentActionModel):
    """The paper's autoencoder with a finite-scalar-quantised latent."""

    def __init__(self, segment_len: int, n_actions: int, levels: list[int],
                 encoder_hidden: list[int], decoder_hidden: list[int],
                 fsq_noise_fraction: float = 0.0):
        super().__init__(segment_len, n_actions, len(levels), encoder_hidden, decoder_hidden,
                         encoder_out=len(levels))
        self.fsq = FSQ(levels, fsq_noise_fraction)

    def latent(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Straight-through quantised z; FSQ needs no regulariser."""
        return self.fsq(self.encoder(x)), torch.zeros((), device=x.device)

    def infer_latent(self, x: torch.Tensor) -> torch.Tensor:
        """Quantised code vector."""
        return self.fsq(self.encoder(x))
