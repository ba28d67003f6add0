"""What a predictor is: a name, a content hash and one method from a trial to actions.

Shape legend: T history steps, K start states, n steps to predict.
- history [T+1, 2, 2] (m): the bank's `model_input`, joint positions (robot first) ending at
  the segment's end, rounded as the participant is shown them;
- starts [K, 2, 2] (m): each start state's robot and human position;
- headings [K] (rad): each start state's robot heading (the world's drawing heading);
- the answer's actions [K, n, 2] (m/s): the robot's velocity over each of the n steps.

A predictor that also reads the scene (`reads_scene = True`, as the coarse observers of
app/observers/predictor.py) is asked with `shown=`: what the participant is shown for the
trial (app/study/trial_payload.py: the scene, dt, the example clips, the segment and the start
states with their headings, the click limits). A lab's plug-in may declare it too.

`content_hash` names what makes the answers reproducible (a checkpoint's content hash; for a
code predictor a hash of its parameters and version, `code_hash`): the bank stores it beside
every answer, and a server recomputes the answers at start-up and refuses a bank whose stored
hash or actions its installed predictor does not reproduce (app/bank/model_answers.py).
"""

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from app.core.files import json_sha256

NO_CODE = -1  # the code of a predictor without discrete codes


@dataclass(frozen=True)
class PredictorAnswer:
    """One predictor's answer to one trial: actions [K, n, 2] m/s, a code and a latent."""

    actions: np.ndarray
    code: int = NO_CODE
    z: list[float] = field(default_factory=list)


@runtime_checkable
class Predictor(Protocol):
    """A named, reproducible predictor of the robot's next moves."""

    name: str
    content_hash: str

    def answer(self, history: np.ndarray, starts: np.ndarray, headings: np.ndarray,
               dt_s: float, n_steps: int) -> PredictorAnswer:
        """The robot's actions [K, n_steps, 2] (m/s) from every start state."""
        ...


def code_hash(name: str, version: str, params: dict) -> str:
    """sha256 hex of a code predictor's name, version and parameters (canonical JSON)."""
    return json_sha256({"name": name, "version": version, "params": params})


def checked_answer(predictor: Predictor, answer: PredictorAnswer, k: int,
                   n_steps: int) -> PredictorAnswer:
    """`answer` once its actions have the shape [k, n_steps, 2] and are finite (ValueError
    naming the predictor otherwise); their dtype is kept, as the bank rounds what came out."""
    actions = np.asarray(answer.actions)
    if actions.shape != (k, n_steps, 2):
        raise ValueError(f"predictor {predictor.name}: actions must have shape "
                         f"[{k}, {n_steps}, 2], got {list(actions.shape)}")
    if not np.isfinite(actions).all():
        raise ValueError(f"predictor {predictor.name}: actions hold NaN or infinity")
    return PredictorAnswer(actions, int(answer.code), [float(v) for v in answer.z])


def reads_scene(predictor: Predictor) -> bool:
    """True if the predictor answers from what the participant is shown as well."""
    return bool(getattr(predictor, "reads_scene", False))


def ask(predictor: Predictor, history, starts, headings, dt_s: float,
        n_steps: int, shown: dict | None = None) -> PredictorAnswer:
    """The predictor's checked answer to one trial (inputs as float64 arrays); `shown` (the
    trial as the participant sees it) reaches only a predictor that reads the scene."""
    starts = np.asarray(starts, dtype=np.float64)
    scene = {"shown": shown} if reads_scene(predictor) else {}
    answer = predictor.answer(np.asarray(history, dtype=np.float64), starts,
                              np.asarray(headings, dtype=np.float64), float(dt_s), n_steps,
                              **scene)
    return checked_answer(predictor, answer, len(starts), n_steps)
