"""The VAE baseline: same encoder/decoder sizes, Gaussian latent of the same dimension."""

import torch

from app.learning.networks import LatentActionModel


class VAEModel(LatentActionModel):
    """Encoder outputs (mean, log-variance); training samples z, inference uses the mean."""

    def __init__(self, segment_len: int, n_actions: int, latent_dim: int,
                 encoder_hidden: list[int], decoder_hidden: list[int], beta_kl: float):
        super().__init__(segment_len, n_actions, latent_dim, encoder_hidden, decoder_hidden,
                         encoder_out=2 * latent_dim)
        self.beta_kl = beta_kl

    def posterior(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance [B, d] each."""
        mean, log_var = self.encoder(x).chunk(2, dim=-1)
        return mean, log_var.clamp(-10.0, 10.0)

    def latent(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Reparameterised sample in training (mean otherwise) and beta * KL to N(0, I)."""
        mean, log_var = self.posterior(x)
        z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_var) if self.training else mean
        kl = 0.5 * (mean.pow(2) + log_var.exp() - 1 - log_var).sum(-1).mean()
        return z, self.beta_kl * kl

    def infer_latent(self, x: torch.Tensor) -> torch.Tensor:
        """Posterior mean."""
        return self.posterior(x)[0]
