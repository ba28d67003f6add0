"""A vectorised sampling MPC shared by every world.

Shape legend: K candidate control sequences, H horizon steps, U control dimensions.
A world supplies `cost(controls[K, H, U]) -> [K]`, which rolls its own dynamics forward
for all candidates at once and sums its reward terms; the sampler only proposes and picks.
"""

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

CostFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class SamplingMPC:
    """Random shooting around a warm start, refined by a few cross-entropy iterations."""

    horizon: int
    n_samples: int
    control_low: tuple[float, ...]
    control_high: tuple[float, ...]
    iterations: int = 2
    elite_fraction: float = 0.1
    init_std_fraction: float = 0.5

    def __post_init__(self) -> None:
        if self.horizon < 1 or self.n_samples < 4:
            raise ValueError("SamplingMPC needs horizon >= 1 and n_samples >= 4")
        if len(self.control_low) != len(self.control_high):
            raise ValueError("control_low and control_high must have the same length")

    @cached_property
    def _low(self) -> np.ndarray:
        return np.asarray(self.control_low, dtype=np.float64)

    @cached_property
    def _high(self) -> np.ndarray:
        return np.asarray(self.control_high, dtype=np.float64)

    def initial_plan(self) -> np.ndarray:
        """The neutral plan [H, U]: mid-range controls."""
        return np.broadcast_to((self._low + self._high) / 2, (self.horizon, len(self._low))).copy()

    def shift(self, plan: np.ndarray) -> np.ndarray:
        """Warm start for the next step: drop the executed control, repeat the last one."""
        return np.concatenate([plan[1:], plan[-1:]], axis=0)

    def plan(self, cost: CostFn, warm_start: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Best control sequence [H, U] found for `cost`, starting from `warm_start`."""
        low, high = self._low, self._high
        mean = np.clip(warm_start, low, high)
        std = np.broadcast_to(self.init_std_fraction * (high - low), mean.shape).copy()
        best_plan, best_cost = mean, float(cost(mean[None])[0])
        n_elite = max(2, int(self.elite_fraction * self.n_samples))
        for _ in range(self.iterations):
            samples = mean + std * rng.standard_normal((self.n_samples, *mean.shape))
            samples[: len(low) * 2] = self._constant_extremes
            samples = np.clip(samples, low, high)
            costs = cost(samples)
            order = np.argsort(costs, kind="stable")
            if costs[order[0]] < best_cost:
                best_plan, best_cost = samples[order[0]], float(costs[order[0]])
            elites = samples[order[:n_elite]]
            mean, std = elites.mean(axis=0), elites.std(axis=0) + 1e-3 * (high - low)
        return best_plan

    @cached_property
    def _constant_extremes(self) -> np.ndarray:
        """Constant sequences at each control's bounds (others mid-range): cheap coverage."""
        mid = (self._low + self._high) / 2
        rows = []
        for u in range(len(mid)):
            for bound in (self._low[u], self._high[u]):
                row = mid.copy()
                row[u] = bound
                rows.append(np.broadcast_to(row, (self.horizon, len(mid))))
        return np.stack(rows)
