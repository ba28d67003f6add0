"""Every predictor of a bundle, loaded once per server process, answering every bank trial.

At start-up each seed of Ours and the VAE of each world is loaded from the study's bundle, and
each plug-in predictor the bank stores answers of is loaded from its installed distribution
(app/predictors/registry.py); every one is asked every bank trial through the predictor
protocol (app/predictors/protocol.py). The results must equal what the bank stored (same
content hash, same code, actions within ACTION_TOLERANCE_MPS), else the server refuses to
start, naming the predictor: the bank was built from other checkpoints or another version of a
plug-in, a plug-in is not installed, or this machine computes them differently. Requests then
read the primary answers from memory (a few KB), so the hot path does no model work and every
worker holds identical, read-only state. `tomstudy bundle verify` runs the same comparison and
prints how far apart the answers are.
"""

from dataclasses import dataclass, field

import numpy as np

from app.core.alignment import ZERO_SPEED_MPS
from app.predictors.protocol import ask
from app.predictors.registry import UnknownPredictor, distribution
from app.study.trial_payload import predictor_inputs
from app.study.trials import ModelAnswer, TrialRecord

ACTION_TOLERANCE_MPS = 1e-4


class BankMismatch(RuntimeError):
    """The trial bank does not match the loaded checkpoints or plug-in predictors."""


@dataclass(frozen=True)
class Answer:
    """One predictor's answer to one trial."""

    code: int
    actions: np.ndarray  # [K, n, 2] m/s
    content_hash: str


@dataclass
class Agreement:
    """How closely one predictor's (a checkpoint's or a plug-in's) recomputed answers match the
    bank's, over every trial."""

    world: str
    model: str
    seed: int
    content_hash: str
    answers: int = 0
    max_metres: float = 0.0  # largest |stored - recomputed| action times dt: one step's position
    max_degrees: float = 0.0  # largest angle between a stored and a recomputed action
    codes_changed: list[str] = field(default_factory=list)  # trial ids
    hash_mismatch: str = ""  # the hash the bank stored, when it is not the predictor's
    max_mps: float = 0.0
    missing: str = ""  # why the predictor could not be loaded (a plug-in not installed)

    @property
    def ok(self) -> bool:
        """True if every answer is within tolerance, with the same code and predictor."""
        return (not self.missing and not self.hash_mismatch and not self.codes_changed
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


def trial_inputs(bank, trial: TrialRecord) -> tuple:
    """What every predictor is asked for one trial of a loaded bank (predictor_inputs)."""
    return predictor_inputs(bank.world(trial.world), bank.data.steps_to_predict, trial)


def agreement_of(predictor_of, key: tuple) -> tuple:
    """The predictor of (world, name, seed) and a fresh Agreement; None and an Agreement
    saying why when the predictor cannot be had (a plug-in not installed)."""
    try:
        predictor = predictor_of(*key)
    except UnknownPredictor as err:
        return None, Agreement(*key, "", missing=str(err))
    return predictor, Agreement(*key, predictor.content_hash)


def recompute(bank, predictor_of) -> tuple[dict[str, dict[str, Answer]], list[Agreement]]:
    """Ask every predictor every bank trial: the primary answers per trial id, and how each
    predictor's answers agree with the stored ones. `predictor_of(world, name, seed)` gives a
    Predictor (a bundle's `predictor`), or raises UnknownPredictor."""
    answers: dict[str, dict[str, Answer]] = {}
    agreements: dict[tuple, tuple] = {}
    for trial in bank.by_id.values():
        asked = trial_inputs(bank, trial)
        for name, family in trial.predictions.items():
            for index, stored in enumerate(family):
                key = (trial.world, name, stored.seed)
                if key not in agreements:
                    agreements[key] = agreement_of(predictor_of, key)
                predictor, check = agreements[key]
                if predictor is None:
                    continue
                if stored.content_hash != predictor.content_hash:
                    check.hash_mismatch = stored.content_hash
                    continue
                answer = ask(predictor, *asked)
                actions = answer.actions.astype(np.float64)
                check.add(trial, stored, answer.code, actions, asked[3])
                if index == 0:
                    answers.setdefault(trial.trial_id, {})[name] = Answer(
                        code=answer.code, actions=actions, content_hash=predictor.content_hash)
    checks = [check for _, check in agreements.values()]
    return answers, sorted(checks, key=lambda a: (a.world, a.model, a.seed))


def mismatch_message(check: Agreement) -> str:
    """Why one predictor's answers are refused, naming it and the first trial concerned."""
    name = f"{check.world}/{check.model}" + (f" seed {check.seed}" if check.seed >= 0 else "")
    if check.missing:
        return f"{name}: {check.missing}"
    if check.hash_mismatch:
        return (f"{name}: the bank holds answers of {check.hash_mismatch[:12]}, the "
                f"predictor here is {check.content_hash[:12]}")
    if check.codes_changed:
        return (f"{name}: this machine encodes {len(check.codes_changed)} trial(s) to another "
                f"code than the bank stored (first: {check.codes_changed[0]})")
    return (f"{name}: answers differ from the bank's by up to {check.max_mps:.2g} m/s "
            f"({check.max_degrees:.3g} deg), more than {ACTION_TOLERANCE_MPS} m/s")


def agreement_lines(checks: list[Agreement], plugins: dict[str, dict]) -> list[str]:
    """What `tomstudy bundle verify` prints: one row per predictor (a plug-in's seed is '-'),
    then, per plug-in, the distribution the bundle was frozen with and the installed one."""
    lines = [f"{'world':<14}{'model':<16}{'seed':>5}{'answers':>9}{'max m':>11}{'max deg':>10}"
             f"{'codes':>7}  verdict"]
    for c in checks:
        seed = str(c.seed) if c.seed >= 0 else "-"
        lines.append(f"{c.world:<14}{c.model:<16}{seed:>5}{c.answers:>9}{c.max_metres:>11.2e}"
                     f"{c.max_degrees:>10.2e}{len(c.codes_changed):>7}  "
                     f"{'ok' if c.ok else 'MISMATCH'}")
    lines.append(f"max m = largest |stored - recomputed| action x dt (one step's position); "
                 f"codes = trials encoded to another code; ok = same checkpoint, observer or "
                 f"plug-in version, same codes, actions within {ACTION_TOLERANCE_MPS} m/s")
    lines += [plugin_line(name, entry) for name, entry in plugins.items()]
    lines += [f"{c.world}/{c.model}: {c.missing}" for c in checks if c.missing]
    return lines


def plugin_line(name: str, frozen: dict) -> str:
    """A plug-in's frozen and installed distribution, for the verify report."""
    here = distribution(name)
    installed = f"{here['distribution']} {here['version']}" if here["distribution"] else \
        "not installed"
    return (f"plug-in {name}: frozen with {frozen['distribution']} {frozen['version']} "
            f"({frozen['content_hash'][:12]}), installed: {installed}")


class ModelAnswers:
    """Every predictor of a study's bundle, verified against its bank; the primary answers per
    trial id."""

    def __init__(self, bundle) -> None:
        self._answers, self.agreements = recompute(bundle.bank, bundle.predictor)
        refused = [mismatch_message(check) for check in self.agreements if not check.ok]
        if refused:
            raise BankMismatch(f"{bundle.root}: the bank's stored model answers do not match "
                               f"its predictors on this machine: {'; '.join(refused)}; run "
                               f"`tomstudy bundle verify` for the figures")

    def answers(self, trial_id: str) -> dict[str, Answer]:
        """Every predictor's primary answer to a bank trial (Ours, the VAE, each plug-in)."""
        return self._answers[trial_id]
