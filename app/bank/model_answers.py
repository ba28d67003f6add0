"""Every checkpoint of a bundle, loaded once per server process, answering every bank trial.

At start-up each seed of Ours and the VAE of each world is loaded from the study's bundle and
run on every bank trial's model input and start states. The results must equal what the bank
stored (same content hash, same code, actions within ACTION_TOLERANCE_MPS), else the server
refuses to start: the bank was built from other checkpoints, or this machine computes them
differently. Requests then read the primary seed's recomputed answers from memory (a few KB),
so the hot path does no model work and every worker holds identical, read-only state.
`tomstudy bundle verify` runs the same comparison and prints how far apart the answers are.
"""

from dataclasses import dataclass, field

import numpy as np

from analysis.alignment import ZERO_SPEED_MPS
from app.study.trials import ModelAnswer, TrialRecord

ACTION_TOLERANCE_MPS = 1e-4


class BankMismatch(RuntimeError):
    """The trial bank does not match the loaded checkpoints."""


@dataclass(frozen=True)
class Answer:
    """One model's answer to one trial."""

    code: int
    actions: np.ndarray  # [K, n, 2] m/s
    content_hash: str


@dataclass
class Agreement:
    """How closely one checkpoint's recomputed answers match the bank's, over every trial."""

    world: str
    model: str
    seed: int
    content_hash: str
    answers: int = 0
    max_metres: float = 0.0  # largest |stored - recomputed| action times dt: one step's position
    max_degrees: float = 0.0  # largest angle between a stored and a recomputed action
    codes_changed: list[str] = field(default_factory=list)  # trial ids
    hash_mismatch: str = ""  # the hash the bank stored, when it is not the checkpoint's
    max_mps: float = 0.0

    @property
    def ok(self) -> bool:
        """True if every answer is within tolerance, with the same code and checkpoint."""
        return (not self.hash_mismatch and not self.codes_changed
                and self.max_mps <= ACTION_TOLERANCE_MPS)

    def add(self, trial: TrialRecord, stored: ModelAnswer, code: int, actions: np.ndarray,
            dt_s: float) -> None:
        """Fold one trial's stored and recomputed answer into the figures."""
        stored_actions = np.asarray(stored.actions, dtype=np.float64)
        gap = float(np.abs(stored_actions - actions).max())
        self.answers += 1
        self.max_mps = max(self.max_mps, gap)
        self.max_metres = max(self.max_metres,
                              float(np.linalg.norm(stored_actions - actions, axis=-1).max()) * dt_s)
        self.max_degrees = max(self.max_degrees, largest_angle_deg(stored_actions, actions))
        if code != stored.code:
            self.codes_changed.append(trial.trial_id)


def largest_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The largest angle [deg] between paired action vectors that both have a direction."""
    norms = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    moving = norms > ZERO_SPEED_MPS ** 2
    if not moving.any():
        return 0.0
    cos = (a * b).sum(-1)[moving] / norms[moving]
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())


def recompute(bank, checkpoints) -> tuple[dict[str, dict[str, Answer]], list[Agreement]]:
    """Run every checkpoint on every bank trial: the primary seed's answers per trial id, and how
    each checkpoint's answers agree with the stored ones. `checkpoints(world, model, seed)` gives
    a loaded TrainedModel."""
    answers: dict[str, dict[str, Answer]] = {}
    agreements: dict[tuple, Agreement] = {}
    for trial in bank.by_id.values():
        states = np.array([[s.robot, s.human] for s in trial.start_states], dtype=np.float32)
        dt_s = bank.world(trial.world).dt_s
        for model_name, family in trial.predictions.items():
            for index, stored in enumerate(family):
                model = checkpoints(trial.world, model_name, stored.seed)
                key = (trial.world, model_name, stored.seed)
                check = agreements.setdefault(key, Agreement(*key, model.content_hash))
                if stored.content_hash != model.content_hash:
                    check.hash_mismatch = stored.content_hash
                    continue
                _, code, actions = model.trial(np.asarray(trial.model_input), states)
                actions = actions.astype(np.float64)
                check.add(trial, stored, int(code), actions, dt_s)
                if index == 0:
                    answers.setdefault(trial.trial_id, {})[model_name] = Answer(
                        code=int(code), actions=actions, content_hash=model.content_hash)
    return answers, sorted(agreements.values(), key=lambda a: (a.world, a.model, a.seed))


def mismatch_message(check: Agreement) -> str:
    """Why one checkpoint's answers are refused, naming it and the first trial concerned."""
    name = f"{check.world}/{check.model} seed {check.seed}"
    if check.hash_mismatch:
        return (f"{name}: the bank holds answers of checkpoint {check.hash_mismatch[:12]}, "
                f"the bundle's checkpoint is {check.content_hash[:12]}")
    if check.codes_changed:
        return (f"{name}: this machine encodes {len(check.codes_changed)} trial(s) to another "
                f"code than the bank stored (first: {check.codes_changed[0]})")
    return (f"{name}: answers differ from the bank's by up to {check.max_mps:.2g} m/s "
            f"({check.max_degrees:.3g} deg), more than {ACTION_TOLERANCE_MPS} m/s")


class ModelAnswers:
    """Every checkpoint of a study's bundle, verified against its bank; the primary seed's
    answers per trial id."""

    def __init__(self, bundle) -> None:
        self._answers, self.agreements = recompute(bundle.bank, bundle.model)
        refused = [mismatch_message(check) for check in self.agreements if not check.ok]
        if refused:
            raise BankMismatch(f"{bundle.root}: the bank's stored model answers do not match "
                               f"its checkpoints on this machine: {'; '.join(refused)}; run "
                               f"`tomstudy bundle verify` for the figures")

    def answers(self, trial_id: str) -> dict[str, Answer]:
        """The primary seed's answers of both models to a bank trial."""
        return self._answers[trial_id]
