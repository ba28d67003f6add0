"""The coarse observers of the pre-registered family as predictors: stored, verified and
exported beside Ours and the VAE.

Each coarse variant (app/observers/family.py: coarse, coarse_scene, coarse_momentum) answers
every bank trial through the predictor protocol from what the participant is shown (the scene,
the example clips, the segment and the start states: it `reads_scene`). Its answer is its
expected move, deterministic: the intents it may act on, each walked without noise, averaged
with its posterior weights (one intent where the config takes the posterior's mode). The other
two observers of the family are already the bank's own columns: the precise observer is the
world's policy (`policy`), the constant-velocity observer is `cv`.

The content hash covers the variant and every observer parameter's value (not its source
text), so a bank answered under other parameters is refused at start-up like another
checkpoint.
"""

from dataclasses import dataclass

import numpy as np

from app.core.contracts import COARSE_OBSERVERS
from app.observers.config import ObserversConfig
from app.observers.family import coarse_options
from app.predictors.protocol import PredictorAnswer, code_hash

VERSION = "1"


def parameter_values(node):
    """A config dump with every `{value, source}` pair reduced to its value."""
    if isinstance(node, dict):
        if "value" in node and "source" in node:
            return node["value"]
        return {key: parameter_values(child) for key, child in node.items()}
    return node


@dataclass(frozen=True)
class ObserverPredictor:
    """One coarse observer variant answering from what the participant is shown."""

    name: str
    observers: ObserversConfig
    reads_scene = True

    def __post_init__(self) -> None:
        if self.name not in COARSE_OBSERVERS:
            raise ValueError(f"observer {self.name!r}: not one of {', '.join(COARSE_OBSERVERS)}")

    @property
    def content_hash(self) -> str:
        """sha256 of the variant, the code version and the observer parameters' values."""
        return code_hash(self.name, VERSION,
                         parameter_values(self.observers.model_dump(mode="json")))

    def answer(self, history: np.ndarray, starts: np.ndarray, headings: np.ndarray,
               dt_s: float, n_steps: int, shown: dict | None = None) -> PredictorAnswer:
        """The posterior-weighted mean of the noise-free walks to each intent it may act on."""
        if shown is None:
            raise ValueError(f"predictor {self.name}: reads the scene, but no trial was shown")
        options = coarse_options(self.name, shown, starts[:, 0], self.observers)
        weights = np.array([w for w, _ in options])
        actions = np.array([a for _, a in options])
        expected = np.tensordot(weights / weights.sum(), actions, axes=1)
        return PredictorAnswer(expected[:, :n_steps])


def observer_predictors(observers: ObserversConfig) -> list[ObserverPredictor]:
    """Every coarse observer variant under one observers config."""
    return [ObserverPredictor(name, observers) for name in COARSE_OBSERVERS]
