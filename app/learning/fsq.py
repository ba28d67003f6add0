"""Finite scalar quantisation (the paper's level set) for training and the server's inference.

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

The maths is written once, as functions over the operations numpy arrays and torch tensors
share: training runs them on tensors inside the `FSQ` module (adding the straight-through
gradient and the noise), the study server's numpy inference (app.learning.checkpoint) runs
the very same functions on arrays. Both round half to even.

Against the reference `vector_quantize_pytorch.FSQ`: for odd L the codes and indices are
equal (tests/learning/test_fsq.py). For even L they differ by design: the reference's
default level set keeps 0 as a level and is therefore lopsided (L=4 gives {-1, -0.5, 0, 0.5};
L=2 it refuses), while the paper's set is symmetric and reaches both ends ({-1, 1} for L=2,
{-1, -1/3, 1/3, 1} for L=4). The reference built with `preserve_symmetry=True` equals ours.
"""

import numpy as np
import torch
from torch import nn


def _namespace(array):
    """numpy for numpy arrays, torch for tensors: the two libraries these functions serve."""
    return np if isinstance(array, np.ndarray | np.generic) else torch


def _cast(array, dtype: str):
    """`array` as "int64" or "float32" in its own library (torch's cast drops the gradient
    of a float tensor turned integer, where torch.asarray would refuse)."""
    xp = _namespace(array)
    return array.astype(getattr(np, dtype)) if xp is np else array.to(getattr(torch, dtype))


def mixed_radix_basis(levels: list[int]) -> list[int]:
    """Place value of each channel's level index in a code index: [1, L0, L0*L1, ...]."""
    return [int(v) for v in np.cumprod([1, *levels[:-1]])]


def level_indices(z, levels):
    """Level index k per channel of unbounded z [.., d], as whole numbers of z's float type."""
    xp = _namespace(z)
    return xp.round((levels - 1) / 2 * (xp.tanh(z) + 1))


def level_values(k, levels):
    """Level indices [.., d] (float) -> code values in [-1, 1]."""
    return 2 * k / (levels - 1) - 1


def quantize(z, levels):
    """Unbounded z [.., d] -> its code vector [.., d], each channel on its level set."""
    return level_values(level_indices(z, levels), levels)


def codes_to_indices(codes, levels, basis):
    """Code vectors [.., d] -> integer code indices [..] (channel 0 least significant)."""
    xp = _namespace(codes)
    k = _cast(xp.round((codes + 1) * (levels - 1) / 2), "int64")
    return xp.sum(k * basis, axis=-1)


def indices_to_codes(indices, levels, basis):
    """Integer code indices [..] -> code vectors [.., d] (float32)."""
    k = (_cast(indices, "int64")[..., None] // basis) % _cast(levels, "int64")
    return level_values(_cast(k, "float32"), levels)


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
        self.register_buffer("basis", torch.tensor(mixed_radix_basis(self.levels_list),
                                                   dtype=torch.int64), persistent=False)

    @property
    def codebook_size(self) -> int:
        """Number of distinct codes, the product of the levels."""
        return int(np.prod(self.levels_list))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Quantised codes; the gradient passes straight through the rounding to tanh(z)."""
        bounded = torch.tanh(z)
        out = bounded + (quantize(z, self.levels) - bounded).detach()
        if self.training and self.noise_fraction > 0:
            out = self._substitute_noise(bounded, out)
        return out

    def _substitute_noise(self, bounded: torch.Tensor, rounded: torch.Tensor) -> torch.Tensor:
        """Replace a random `noise_fraction` of entries by tanh(z) + uniform noise, one bin wide."""
        bin_width = 2 / (self.levels - 1)
        noisy = bounded + (torch.rand_like(bounded) - 0.5) * bin_width
        chosen = torch.rand_like(bounded) < self.noise_fraction
        return torch.where(chosen, noisy, rounded)

    def codes_to_indices(self, codes: torch.Tensor) -> torch.Tensor:
        """Code vectors [.., d] -> integer indices [..]."""
        return codes_to_indices(codes, self.levels, self.basis)

    def indices_to_codes(self, indices: torch.Tensor) -> torch.Tensor:
        """Integer indices [..] -> code vectors [.., d]."""
        return indices_to_codes(indices, self.levels, self.basis)

    def all_codes(self) -> torch.Tensor:
        """Every code vector, in index order [codebook_size, d]."""
        return self.indices_to_codes(torch.arange(self.codebook_size))
