"""Ours and the VAE, loaded once per server process, answering every trial of the bank.

At start-up both checkpoints of each world are loaded and run on every bank trial's
segment and start states. The results must equal what the bank stored (same content
hash, same code, actions within 1e-4 m/s), else the server refuses to start: the bank
was built from other checkpoints. Requests then read the recomputed answers from memory
(a few KB), so the hot path does no model work and every worker holds identical,
read-only state.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.layout import Layout
from app.study.config import StudyConfig
from app.study.trials import TrialBank

ACTION_TOLERANCE_MPS = 1e-4


class BankMismatch(RuntimeError):
    """The trial bank does not match the loaded checkpoints."""


@dataclass(frozen=True)
class Answer:
    """One model's answer to one trial."""

    code: int
    actions: np.ndarray  # [K, n, 2] m/s
    content_hash: str


class ModelAnswers:
    """Both models of every world of a study, and their answers per trial id."""

    def __init__(self, config: StudyConfig, bank: TrialBank, data_dir: Path) -> None:
        from app.learning.checkpoint import load_model

        layout = Layout(data_dir)
        self.models = {world: {name: load_model(layout.resolve(getattr(paths, name)),
                                                world=world)
                               for name in ("ours", "vae")}
                       for world, paths in config.models.items()
                       if world in bank.data.worlds}
        self._answers = {tid: self._run(trial) for tid, trial in bank.by_id.items()}

    def _run(self, trial) -> dict[str, Answer]:
        states = np.array([[s.robot, s.human] for s in trial.start_states], dtype=np.float32)
        answers = {}
        for model_name, model in self.models[trial.world].items():
            stored = trial.predictions[model_name]
            if stored.content_hash != model.content_hash:
                raise BankMismatch(f"{trial.trial_id}: bank holds {model_name} "
                                   f"{stored.content_hash[:12]}, server loaded "
                                   f"{model.content_hash[:12]}; rebuild the bank "
                                   f"(tomstudy build-trials)")
            _, code, actions = model.trial(np.asarray(stored.segment_positions), states)
            if code != stored.code or not np.allclose(actions, stored.actions,
                                                      atol=ACTION_TOLERANCE_MPS):
                raise BankMismatch(f"{trial.trial_id}: {model_name} answers differ from the bank")
            answers[model_name] = Answer(code=int(code), actions=actions.astype(np.float64),
                                         content_hash=model.content_hash)
        return answers

    def answers(self, trial_id: str) -> dict[str, Answer]:
        """Both models' answers to a bank trial."""
        return self._answers[trial_id]
