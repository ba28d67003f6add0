"""The study's own predictors in the protocol: a checkpoint (Ours or the VAE) and constant
velocity. The world's policy is the ground truth the bank stores beside them, not a predictor.
"""

from dataclasses import dataclass

import numpy as np

from app.data.trajectory import ROBOT
from app.predictors.protocol import PredictorAnswer, code_hash

CONSTANT_VELOCITY = "cv"


@dataclass(frozen=True)
class CheckpointPredictor:
    """A loaded checkpoint (app/learning/checkpoint.py's TrainedModel) as a predictor: its
    name is the model's (ours, vae), its content hash the checkpoint's."""

    model: object  # TrainedModel

    @property
    def name(self) -> str:
        """The model's name (ours or vae)."""
        return self.model.name

    @property
    def content_hash(self) -> str:
        """The checkpoint's content hash."""
        return self.model.content_hash

    def answer(self, history: np.ndarray, starts: np.ndarray, headings: np.ndarray,
               dt_s: float, n_steps: int) -> PredictorAnswer:
        """Encode the history to a latent and code, decode actions from every start state."""
        if n_steps != self.model.n_actions:
            raise ValueError(f"predictor {self.name}: the checkpoint predicts "
                             f"{self.model.n_actions} steps, {n_steps} were asked for")
        z, code, actions = self.model.trial(history, starts)
        return PredictorAnswer(actions, int(code), [float(v) for v in z])


@dataclass(frozen=True)
class ConstantVelocity:
    """The robot keeps the velocity of the history's last step, from every start state."""

    name: str = CONSTANT_VELOCITY
    version: str = "1"

    @property
    def content_hash(self) -> str:
        """sha256 of the name and version (it has no parameters)."""
        return code_hash(self.name, self.version, {})

    def answer(self, history: np.ndarray, starts: np.ndarray, headings: np.ndarray,
               dt_s: float, n_steps: int) -> PredictorAnswer:
        """The last step's robot velocity, the same for every start state and step."""
        velocity = (history[-1, ROBOT] - history[-2, ROBOT]) / dt_s
        return PredictorAnswer(np.broadcast_to(velocity, (len(starts), n_steps, 2)).copy())
