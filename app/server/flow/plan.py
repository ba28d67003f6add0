"""A participant's plan: the phases, the typed steps, and the balanced assignment.

A plan is fixed at session start and stored as JSON in `Participant.plan`; `position`
indexes into it. `Phase` is the one place the phase names are spelled: the server
answers them in every state, and the participant page receives the list with the page
(routes/pages.py), so adding a phase is this enum plus one handler in app.js. The
stored JSON keeps its shape: steps are parsed on read and dumped on write.
"""

import secrets
from dataclasses import dataclass
from enum import StrEnum
from itertools import permutations
from typing import ClassVar

import numpy as np
from pydantic import field_validator

from app.assignment import least_used, pick_by_arm
from app.configio import StrictModel
from app.server.storage.tables import Participant
from app.study.config import StudyConfig
from app.study.errors import Refused
from app.study.trials import TrialBank


class Phase(StrEnum):
    """Where a session is; a step of the plan is one phase (a trial phase once per trial)."""

    CONSENT = "consent"
    INSTRUCTIONS = "instructions"
    WORLD_INTRO = "world_intro"  # opens a world's part: what its scene shows
    PRACTICE = "practice"  # a practice trial (not scored)
    PRACTICE_OVER = "practice_over"  # between a part's practice and its scored trials
    TRIAL = "trial"  # a main trial or an attention check (the browser cannot tell which)
    SURVEY = "survey"
    DONE = "done"


TRIAL_PHASES = (Phase.PRACTICE, Phase.TRIAL)
PART_PHASES = (Phase.WORLD_INTRO, Phase.PRACTICE_OVER)  # screens that only ask to go on
BEFORE_TRIALS = (Phase.CONSENT, Phase.INSTRUCTIONS)  # a device screen-out may end these


class Step(StrictModel):
    """One plan entry that is not a trial: only its phase (stored as `{"phase": ...}`)."""

    phase: Phase


class WorldStep(Step):
    """A step inside one world's part; its phase is one of the subclass' `PHASES`."""

    PHASES: ClassVar[tuple[Phase, ...]] = ()
    world: str
    world_position: int  # the world's place in this session's world order

    @field_validator("phase")
    @classmethod
    def _phase_fits(cls, phase: Phase) -> Phase:
        if phase not in cls.PHASES:
            raise ValueError(f"a {cls.__name__}'s phase is one of {', '.join(cls.PHASES)}")
        return phase


class PartStep(WorldStep):
    """A screen of one world's part (its introduction, or the end of its practice)."""

    PHASES: ClassVar[tuple[Phase, ...]] = PART_PHASES


class TrialStep(WorldStep):
    """One trial of the plan; `ref` is the only id of it the browser sees.

    `ref` is random per session, so neither the bank's trial id nor whether this is an
    attention check can be read from the browser's payload.
    """

    PHASES: ClassVar[tuple[Phase, ...]] = TRIAL_PHASES
    trial_id: str  # the bank's id
    ref: str
    trial_index: int  # the trial's place within its world's block
    attention_check: bool


def parse_step(raw: dict) -> Step:
    """A stored plan entry as its typed step (TrialStep in a trial phase, PartStep on a
    part's screens)."""
    model = (TrialStep if raw["phase"] in TRIAL_PHASES
             else PartStep if raw["phase"] in PART_PHASES else Step)
    return model.model_validate(raw)


def parse_plan(raw: list[dict]) -> list[Step]:
    """A stored plan as typed steps."""
    return [parse_step(entry) for entry in raw]


def dump_plan(steps: list[Step]) -> list[dict]:
    """Typed steps as the JSON the plan column stores."""
    return [step.model_dump(mode="json") for step in steps]


def current_step(participant: Participant) -> Step:
    """The step the participant is at; the last one, done, once the session has ended.

    An ending before the plan is through (declined consent, screened out) leaves `position`
    where the session ended, so it still counts the steps the person really took.
    """
    if participant.completed or participant.ended_at is not None:
        return parse_step(participant.plan[-1])
    return parse_step(participant.plan[min(participant.position, len(participant.plan) - 1)])


def has_consented(participant: Participant) -> bool:
    """True once the session is past its consent step (the plan's first, layout_plan)."""
    return participant.position > 0


def trial_steps(participant: Participant) -> list[tuple[int, TrialStep]]:
    """(position, step) of every trial of the plan, practice included."""
    steps = enumerate(parse_plan(participant.plan))
    return [(i, step) for i, step in steps if isinstance(step, TrialStep)]


def expect_phase(participant: Participant, *phases: Phase) -> Step:
    """The current step if its phase is one of `phases`, else 409."""
    step = current_step(participant)
    if step.phase not in phases:
        raise Refused(409, f"phase: this request belongs to {' or '.join(phases)}, "
                           f"but the session is at {step.phase}")
    return step


def part_steps(participant: Participant, world_position: int) -> list[TrialStep]:
    """The trials (practice included) of one part of the participant's plan, in order."""
    return [step for _, step in trial_steps(participant) if step.world_position == world_position]


def expect_trial(participant: Participant, ref: str) -> TrialStep:
    """The current trial step if the browser's opaque `ref` names it; 409/404 otherwise."""
    step = expect_phase(participant, *TRIAL_PHASES)
    if step.ref == ref:
        return step
    if any(other.ref == ref for _, other in trial_steps(participant)):
        raise Refused(409, f"trial_id: {ref!r} is not the current trial of this session")
    raise Refused(404, f"trial_id: {ref!r} is not a trial of this session")


# ---------------------------------------------------------------- assignment

@dataclass(frozen=True)
class Usage:
    """How many counted sessions use each world order and each trial (balance.py)."""

    orders: dict[tuple[str, ...], int]
    trials: dict[str, int]


def world_orders(config: StudyConfig) -> list[tuple[str, ...]]:
    """All orders when counterbalanced, else the configured one."""
    if config.counterbalance_world_order:
        return list(permutations(config.worlds))
    return [tuple(config.worlds)]


def assign_plan(config: StudyConfig, bank: TrialBank, usage: Usage,
                rng: np.random.Generator) -> tuple[tuple[str, ...], list[Step]]:
    """Pick the least-used world order and least-exposed trials; lay out the steps."""
    order = least_used(world_orders(config), usage.orders, 1, rng)[0]
    return order, layout_plan(config, bank, order, usage.trials, rng)


def layout_plan(config: StudyConfig, bank: TrialBank, order: tuple[str, ...],
                exposure: dict[str, int], rng: np.random.Generator) -> list[Step]:
    """consent, instructions, one part per world (_part), survey, done."""
    plan = [Step(phase=Phase.CONSENT), Step(phase=Phase.INSTRUCTIONS)]
    for position, world in enumerate(order):
        plan += _part(config, bank, world, position, exposure, rng)
    return plan + [Step(phase=Phase.SURVEY), Step(phase=Phase.DONE)]


def _part(config: StudyConfig, bank: TrialBank, world: str, position: int,
          exposure: dict[str, int], rng: np.random.Generator) -> list[Step]:
    """One world's part: its introduction, its practice and the screen that ends it, then its
    trials with attention checks."""
    steps: list[Step] = [PartStep(phase=Phase.WORLD_INTRO, world=world, world_position=position)]
    pool = [t.trial_id for t in bank.trials_of(world, "practice")]
    practice = least_used(pool, exposure, config.practice_trials, rng)
    steps += [_trial_step(Phase.PRACTICE, tid, world, position, i, False)
              for i, tid in enumerate(practice)]
    if practice:
        steps.append(PartStep(phase=Phase.PRACTICE_OVER, world=world, world_position=position))
    return steps + [_trial_step(Phase.TRIAL, tid, world, position, index, check)
                    for index, (tid, check) in enumerate(_world_block(config, bank, world,
                                                                      exposure, rng))]


def _world_block(config: StudyConfig, bank: TrialBank, world: str, exposure: dict[str, int],
                 rng: np.random.Generator) -> list[tuple[str, bool]]:
    """One world's (trial id, is attention check): main trials of every arm shuffled, checks not
    first."""
    main = [(t.trial_id, t.arm) for t in bank.trials_of(world, "main")]
    chosen = pick_by_arm(main, exposure, config.trials_per_world, rng)
    checks = [t.trial_id for t in bank.trials_of(world, "attention")]
    block = [(tid, False) for tid in chosen]
    for tid in least_used(checks, exposure, config.attention_checks.per_world, rng):
        block.insert(int(rng.integers(1, len(block) + 1)), (tid, True))
    return block


def _trial_step(phase: Phase, trial_id: str, world: str, world_position: int, index: int,
                attention_check: bool) -> TrialStep:
    return TrialStep(phase=phase, trial_id=trial_id, ref=secrets.token_hex(8), world=world,
                     world_position=world_position, trial_index=index,
                     attention_check=attention_check)
