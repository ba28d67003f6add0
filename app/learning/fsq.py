"""Finite scalar quantisation with the paper's symmetric level set.

Shape legend: B batch, d latent channels (= len(levels)).
- z      [B, d] unbounded encoder output
- codes  [B, d] quantised values, channel i in {-1, -1 + 2/(L_i-1), ..., 1}
- k      [B, d] level index per channel, in {0..L_i-1}
- index  [B]    one integer per code; channel 0 is the least significant digit
                (the same mixed-radix order as vector_quantize_pytorch)

Per channel with L levels: k = round((L-1)/2 * (tanh(z) + 1)), z_q = 2k/(L-1) - 1.
The paper prints this formula without the bracket and the -1; its L=2 example
({-1, 1}) fixes the meaning. Gradients pass straight through the rounding:
out = b + (z_q - b).detach() with b = tanh(z), so d out / d b = 1 (as in the reference
FSQ, whose straight-through rounding also sits after the tanh bound). Applying it to the
raw z instead lets z drift far past saturation with nothing pulling it back.

Optional noise substitution (`noise_fraction` > 0, training mode only): for that share of
the entries, the rounding is replaced by uniform noise one bin wide around tanh(z), as in
the noise-approximated symmetric FSQ that introduced this level set. With straight-through
rounding alone the decoder only ever sees the exact levels, so nothing pushes windows of
different behaviour into different bins. With noise, the decoder must predict well from
anywhere within half a bin of the encoder's value. Behaviours that need different
predictions therefore end up at least a bin apart, which is what rounding needs at test
time. Evaluation (model.eval()) always rounds, so codes stay exactly the level set.
"""

import numpy as np
import torch
from torch import nn


class FSQ(nn.Module):
    """Quantise each channel to its own symmetric level set, straight-through."""

    def __init__(self, levels: list[int], noise_fraction: float = 0.0):
        super().__init__()
        if not 0.0 <= noise_fraction <= 1.0:
            raise ValueError(f"noise_fraction must be in [0, 1], got {noise_fraction}")
        self.noise_fraction = float(noise_fraction)
        if not levels or any(int(level) < 2 for level in levels):
            raise ValueError(f"levels must be a non-empty list of integers >= 2, got {levels}")
        self.levels_list = [int(level) for level in levels]
        self.register_buffer("levels", torch.tensor(self.levels_list, dtype=torch.float32),
                             persistent=False)
        basis = np.cumprod([1] + self.levels_list[:-1])
        self.register_buffer("basis", torch.tensor(basis, dtype=torch.int64), persistent=False)

    @property
    def codebook_size(self) -> int:
        """Number of distinct codes, the product of the levels."""
        return int(np.prod(self.levels_list))

    def level_indices(self, z: torch.Tensor) -> torch.Tensor:
        """Integer level index k per channel (no gradient)."""
        half = (self.levels - 1) / 2
        return torch.round(half * (torch.tanh(z) + 1)).long()

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Quantised codes; the gradient passes straight through the rounding to tanh(z)."""
        bounded = torch.tanh(z)
        z_q = self.level_indices_to_codes(self.level_indices(z))
        out = bounded + (z_q - bounded).detach()
        if self.training and self.noise_fraction > 0:
            out = self._substitute_noise(bounded, out)
        return out

    def _substitute_noise(self, bounded: torch.Tensor, rounded: torch.Tensor) -> torch.Tensor:
        """Replace a random `noise_fraction` of entries by tanh(z) + uniform noise, one bin wide."""
        bin_width = 2 / (self.levels - 1)
        noisy = bounded + (torch.rand_like(bounded) - 0.5) * bin_width
        chosen = torch.rand_like(bounded) < self.noise_fraction
        return torch.where(chosen, noisy, rounded)

    def level_indices_to_codes(self, k: torch.Tensor) -> torch.Tensor:
        """Level indices [.., d] -> code values in [-1, 1]."""
        return 2 * k.to(torch.float32) / (self.levels - 1) - 1

    def codes_to_indices(self, codes: torch.Tensor) -> torch.Tensor:
        """Code vectors [.., d] -> integer indices [..]."""
        k = torch.round((codes + 1) * (self.levels - 1) / 2).long()
        return (k * self.basis).sum(dim=-1)

    def indices_to_codes(self, indices: torch.Tensor) -> torch.Tensor:
        """Integer indices [..] -> code vectors [.., d]."""
        k = (indices.long().unsqueeze(-1) // self.basis) % self.levels.long()
        return self.level_indices_to_codes(k)

    def all_codes(self) -> torch.Tensor:
        """Every code vector, in index order [codebook_size, d]."""
        return self.indices_to_codes(torch.arange(self.codebook_size))


def quantize_numpy(z: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """The forward pass of `FSQ` in numpy (same rounding: half to even)."""
    half = (levels - 1) / 2
    k = np.round(half * (np.tanh(z) + 1))
    return (2 * k / (levels - 1) - 1).astype(np.float32)


def codes_to_indices_numpy(codes: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Code vectors [.., d] -> integer indices [..] (numpy twin of `FSQ.codes_to_indices`)."""
    basis = np.cumprod(np.concatenate([[1], levels[:-1]])).astype(np.int64)
    k = np.round((codes + 1) * (levels - 1) / 2).astype(np.int64)
    return (k * basis).sum(axis=-1)


def indices_to_codes_numpy(indices: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Integer indices [..] -> code vectors [.., d] (numpy twin of `FSQ.indices_to_codes`)."""
    levels = np.asarray(levels, dtype=np.int64)
    basis = np.cumprod(np.concatenate([[1], levels[:-1]])).astype(np.int64)
    k = (np.asarray(indices, dtype=np.int64)[..., None] // basis) % levels
    return (2 * k / (levels - 1) - 1).astype(np.float32)
