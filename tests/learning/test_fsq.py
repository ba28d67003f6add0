"""FSQ: level set, index round trip, straight-through gradients, reference implementation.

The same functions quantise torch tensors (training) and numpy arrays (the server's
inference); every comparison below runs both."""

import numpy as np
import pytest
import torch

from app.learning.fsq import (
    FSQ,
    codes_to_indices,
    indices_to_codes,
    mixed_radix_basis,
    quantize,
)


def numpy_levels(levels: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The (levels, basis) arrays the numpy inference passes to the FSQ functions."""
    return (np.asarray(levels, dtype=np.float32),
            np.asarray(mixed_radix_basis(levels), dtype=np.int64))


def level_set(levels: int) -> np.ndarray:
    return 2 * np.arange(levels) / (levels - 1) - 1


def away_from_ties(z: torch.Tensor, levels: list[int], margin: float = 0.01) -> torch.Tensor:
    """Rows whose every channel is not within `margin` of a rounding threshold: there the
    reference's (1 + 1e-3) range stretch or round-half-to-even may legitimately differ."""
    scaled = (torch.tensor(levels) - 1) / 2 * (torch.tanh(z) + 1)
    frac = scaled - scaled.floor()
    return ((frac - 0.5).abs() > margin).all(dim=-1)


@pytest.mark.parametrize("levels", [[2], [3], [4], [5], [8], [2, 2, 2], [3, 5], [5, 5]])
def test_every_output_lies_in_the_channel_level_set(levels):
    fsq = FSQ(levels)
    out = fsq(torch.randn(4000, len(levels)) * 3).detach().numpy()
    for channel, n in enumerate(levels):
        distance = np.abs(out[:, channel, None] - level_set(n)[None]).min(axis=1)
        assert distance.max() < 1e-6
    # the extremes of the paper's symmetric set are reached: {-1, ..., 1}
    assert out.min() == pytest.approx(-1) and out.max() == pytest.approx(1)


def test_paper_example_d3_l2_gives_the_eight_corners():
    fsq = FSQ([2, 2, 2])
    codes = fsq.all_codes().numpy()
    assert len(codes) == 8
    assert {tuple(c) for c in codes} == {(a, b, c) for a in (-1, 1) for b in (-1, 1)
                                         for c in (-1, 1)}


@pytest.mark.parametrize("levels", [[2, 2, 2], [3, 3], [3, 5, 4], [8]])
def test_codes_to_indices_to_codes_round_trips(levels):
    fsq = FSQ(levels)
    indices = torch.arange(fsq.codebook_size)
    codes = fsq.indices_to_codes(indices)
    assert torch.equal(fsq.codes_to_indices(codes), indices)
    assert len({tuple(c) for c in codes.tolist()}) == fsq.codebook_size
    quantised = fsq(torch.randn(500, len(levels)))
    assert torch.allclose(fsq.indices_to_codes(fsq.codes_to_indices(quantised)), quantised)
    lv, basis = numpy_levels(levels)
    assert np.array_equal(codes_to_indices(codes.numpy(), lv, basis), indices.numpy())
    assert np.array_equal(indices_to_codes(indices.numpy(), lv, basis), codes.numpy())


def test_numpy_arrays_and_torch_tensors_give_identical_codes():
    fsq = FSQ([2, 3, 5])
    z = torch.randn(1000, 3) * 2
    lv, basis = numpy_levels([2, 3, 5])
    codes = quantize(z.numpy(), lv)
    assert codes.dtype == np.float32
    assert np.array_equal(codes, fsq(z).detach().numpy())
    assert np.array_equal(codes_to_indices(codes, lv, basis),
                          fsq.codes_to_indices(fsq(z)).numpy())


def test_gradients_pass_straight_through_the_rounding():
    fsq = FSQ([3, 4])
    z = torch.randn(64, 2, requires_grad=True)
    weights = torch.randn(64, 2)
    (fsq(z) * weights).sum().backward()
    # d out / d tanh(z) is the identity; the only factor left is tanh's own derivative
    expected = weights * (1 - torch.tanh(z.detach()) ** 2)
    assert torch.allclose(z.grad, expected, atol=1e-6)
    assert (z.grad != 0).all()


@pytest.mark.parametrize("levels", [[3], [5], [7], [3, 5], [5, 5]])
def test_odd_levels_equal_the_reference_fsq(levels):
    from vector_quantize_pytorch import FSQ as ReferenceFSQ

    z = torch.randn(20000, len(levels)) * 2
    keep = away_from_ties(z, levels)
    assert keep.float().mean() > 0.9
    ref_codes, ref_idx = ReferenceFSQ(levels)(z[None])
    ours = FSQ(levels)
    codes = ours(z)
    assert torch.allclose(codes[keep], ref_codes[0][keep], atol=1e-6)
    assert torch.equal(ours.codes_to_indices(codes)[keep], ref_idx[0][keep].long())
    lv, basis = numpy_levels(levels)  # the server's numpy inference: the same codes
    numpy_codes = quantize(z.numpy(), lv)
    assert np.allclose(numpy_codes[keep], ref_codes[0][keep].numpy(), atol=1e-6)
    assert np.array_equal(codes_to_indices(numpy_codes, lv, basis)[keep],
                          ref_idx[0][keep].numpy())


@pytest.mark.parametrize("levels", [[2], [4], [6], [2, 2, 2], [2, 3, 4]])
def test_even_levels_equal_the_reference_symmetric_mode(levels):
    from vector_quantize_pytorch import FSQ as ReferenceFSQ

    z = torch.randn(20000, len(levels)) * 2
    keep = away_from_ties(z, levels, margin=1e-4)
    ref = ReferenceFSQ(levels, preserve_symmetry=True)
    ref_codes, ref_idx = ref(z[None])
    ours = FSQ(levels)
    codes = ours(z)
    assert torch.allclose(codes[keep], ref_codes[0][keep], atol=1e-6)
    assert torch.equal(ours.codes_to_indices(codes)[keep], ref_idx[0][keep].long())
    assert torch.allclose(ours.all_codes(), ref.implicit_codebook, atol=1e-6)


def test_even_levels_differ_from_the_reference_default_by_design():
    """The reference keeps 0 as a level (lopsided for even L); the paper's set is symmetric."""
    from vector_quantize_pytorch import FSQ as ReferenceFSQ

    reference = ReferenceFSQ([4]).implicit_codebook.flatten().numpy()
    ours = FSQ([4]).all_codes().flatten().numpy()
    assert np.allclose(reference, [-1, -0.5, 0, 0.5])
    assert np.allclose(ours, [-1, -1 / 3, 1 / 3, 1]) and np.allclose(ours, -ours[::-1])
    with pytest.raises(AssertionError, match="preserve_symmetry"):
        ReferenceFSQ([2])  # the paper's L=2 example exists only in the symmetric variant


@pytest.mark.parametrize("levels", [[], [1], [3, 0]])
def test_bad_levels_are_rejected(levels):
    with pytest.raises(ValueError, match="levels"):
        FSQ(levels)


def test_noise_substitution_trains_near_tanh_and_evaluates_on_the_levels():
    levels = [3, 5]
    fsq = FSQ(levels, noise_fraction=1.0)
    z = torch.randn(4000, 2, requires_grad=True)
    bounded = torch.tanh(z.detach())
    half_bin = 1 / (torch.tensor(levels, dtype=torch.float32) - 1)
    noisy = fsq(z)
    assert ((noisy.detach() - bounded).abs() <= half_bin + 1e-6).all()
    # noise, not rounding: almost no training value sits on a level
    assert torch.isin(noisy.detach(), fsq.all_codes().unique()).float().mean() < 0.01
    noisy.sum().backward()
    assert torch.allclose(z.grad, 1 - bounded ** 2, atol=1e-6)
    fsq.eval()
    assert torch.equal(fsq(z).detach(), FSQ(levels)(z).detach())


def test_noise_fraction_picks_that_share_of_entries():
    torch.manual_seed(0)
    fsq = FSQ([3], noise_fraction=0.3)
    z = torch.randn(20000, 1)
    on_levels = torch.isin(fsq(z), torch.tensor([-1.0, 0.0, 1.0])).float().mean()
    assert abs(float(on_levels) - 0.7) < 0.02
    with pytest.raises(ValueError, match="noise_fraction"):
        FSQ([3], noise_fraction=1.5)
