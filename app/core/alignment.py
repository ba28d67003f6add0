"""Alignment error, the study's one metric, defined once for the server and the analysis.

Alignment error = 1 - cos(angle between two action vectors), in [0, 2]: 0 = same
direction, 1 = perpendicular, 2 = opposite. A cosine needs two directions; when either
vector is shorter than ZERO_SPEED_MPS (a model may predict standing still; a person
cannot, the server rejects zero-length moves) the error is defined as 1, the value of
"no directional information" (the mean error of a uniformly random direction).

Only numpy: `app` and `analysis` both import it, and it imports neither.
"""

import numpy as np

ZERO_SPEED_MPS = 1e-6


def has_direction(v: np.ndarray, zero_speed: float = ZERO_SPEED_MPS) -> np.ndarray:
    """Where action vectors v[..., 2] are longer than `zero_speed` (so have a direction)."""
    v = np.asarray(v, dtype=np.float64)
    return np.hypot(v[..., 0], v[..., 1]) > zero_speed


def alignment_error(a: np.ndarray, b: np.ndarray, zero_speed: float = ZERO_SPEED_MPS) -> np.ndarray:
    """1 - cos(angle) between action vectors a[..., 2] and b[..., 2]; 1 where either is ~0."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    norm_a = np.hypot(a[..., 0], a[..., 1])
    norm_b = np.hypot(b[..., 0], b[..., 1])
    defined = (norm_a > zero_speed) & (norm_b > zero_speed)  # has_direction, norms reused
    dot = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.where(defined, dot / (norm_a * norm_b), 0.0)
    return 1.0 - np.clip(cos, -1.0, 1.0)
