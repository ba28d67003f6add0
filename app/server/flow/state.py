"""What a participant's browser is told at each step (GET .../state and every write's answer).

A trial's static part (scene, clips, start states: ~15 KB of numbers) is encoded to JSON
once per process and spliced into each answer: encoding it per request through FastAPI's
`jsonable_encoder` cost ~5 ms, most of a state request.
"""

import json

from app.server.flow.context import StudyContext
from app.server.flow.endings import done_payload
from app.server.flow.plan import (
    PartStep,
    Phase,
    Step,
    TrialStep,
    current_step,
    part_steps,
    trial_steps,
)
from app.server.storage.tables import Participant
from app.study.consent import consent_sections, render
from app.study.trial_payload import practice_feedback, trial_payload


def progress_of(participant: Participant) -> dict:
    """Trials (practice included) done and in total."""
    trial_positions = [i for i, _ in trial_steps(participant)]
    done = sum(1 for i in trial_positions if i < participant.position)
    return {"done": done, "total": len(trial_positions)}


def step_payload(ctx: StudyContext, participant: Participant, step: Step) -> dict:
    """What a non-trial phase needs: texts, the survey or the completion code."""
    cfg = ctx.config
    if step.phase == Phase.CONSENT:
        advert = ctx.estimate().advert
        return {"title": cfg.title, "text": render(cfg.consent_text, advert),
                "sections": consent_sections(cfg, advert)}
    if step.phase == Phase.INSTRUCTIONS:
        return {"title": cfg.title, "text": cfg.instructions_text,
                "world_order": participant.world_order.split(",")}
    if step.phase == Phase.SURVEY:
        return {"questions": [q.model_dump() for q in cfg.survey]}
    if isinstance(step, PartStep):
        return part_payload(ctx, participant, step)
    return done_payload(cfg, participant)


def part_payload(ctx: StudyContext, participant: Participant, step: PartStep) -> dict:
    """A part's screen: which part of how many, its world explained, and its trial counts."""
    intro = ctx.config.world_intros[step.world]
    trials = part_steps(participant, step.world_position)
    return {**part_numbers(participant, step.world_position), "world": step.world,
            "title": intro.title, "text": intro.text,
            "scene": ctx.bank.world(step.world).scene,
            "practice_trials": sum(t.phase == Phase.PRACTICE for t in trials),
            "trials": sum(t.phase == Phase.TRIAL for t in trials)}


def part_numbers(participant: Participant, world_position: int) -> dict:
    """`part` (1-based) of `parts`: how the page names a world's place in the session."""
    return {"part": world_position + 1, "parts": len(participant.world_order.split(","))}


def step_fields(participant: Participant, step: TrialStep) -> dict:
    """The parts of a trial payload that depend on the participant's plan.

    The browser gets the step's random `ref` as `trial_id` and no attention-check flag:
    nothing in the payload tells a script which trial is the check. `number` of `of` counts
    the part's practice trials, or its scored trials (checks included), from 1.
    """
    same_kind = [t for t in part_steps(participant, step.world_position) if t.phase == step.phase]
    return {"trial_id": step.ref, "world": step.world,
            "index_in_world": step.trial_index, "world_position": step.world_position,
            "is_practice": step.phase == Phase.PRACTICE,
            **part_numbers(participant, step.world_position),
            "number": step.trial_index + 1, "of": len(same_kind)}


def static_trial(ctx: StudyContext, trial_id: str) -> dict:
    """The parts of a trial payload that are the same for everyone, with the prediction view."""
    trial = ctx.bank.by_id[trial_id]
    payload = {**trial_payload(ctx.bank, trial), "view": ctx.view(trial.world).payload()}
    if trial.kind == "practice":
        payload["feedback"] = practice_feedback(ctx.bank.world(trial.world), trial)
    return payload


def state_json(ctx: StudyContext, participant: Participant, draft: dict | None = None) -> str:
    """`{phase, progress: {done, total}, step}` as JSON; a trial's static part is encoded once.

    `draft` is the trial's in-progress answer (drafts.py), handed back so a reloaded page
    resumes where it was.
    """
    step = current_step(participant)
    state = {"phase": step.phase, "progress": progress_of(participant)}
    if not isinstance(step, TrialStep):
        return json.dumps({**state, "step": step_payload(ctx, participant, step)})
    static = ctx.trial_json.get(step.trial_id)
    if static is None:
        static = json.dumps(static_trial(ctx, step.trial_id))
        ctx.trial_json[step.trial_id] = static
    head = json.dumps({**state, "step": {**step_fields(participant, step), "draft": draft}})
    return f"{head[:-2]}, {static[1:]}}}"


