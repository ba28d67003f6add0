"""A trial's answer in progress, kept on the server so that a reload resumes it.

The page saves the current trial's clicks, their times, the undo history, the start state
being answered and when the trial was first shown after every change (PUT .../draft), and
GET .../state hands the draft back with the trial. It is kept on the server rather than in
the browser because a server copy survives a crash, a cleared browser or a change of
device, can be handed to the tab that takes over (tabs.py), and shows the researcher what
was resumed. One row per session, written by one upsert; a save with a lower `seq` than the
stored one (a late retry) changes nothing, and the row goes in the transaction that stores
the trial.
"""

from sqlalchemy import delete, or_, select
from sqlmodel import Session

from app.server.flow.context import StudyContext
from app.server.flow.plan import TrialStep, current_step, expect_trial
from app.server.schemas import DraftSave
from app.server.storage.db import upsert
from app.server.storage.tables import Participant, TrialDraft, utcnow
from app.study.errors import Refused


def save_draft(db: Session, ctx: StudyContext, participant: Participant, body: DraftSave) -> int:
    """Keep `body` as the current trial's draft unless a newer one is stored; the stored seq."""
    step = expect_trial(participant, body.trial_id)
    check_shape(ctx, step, body)
    table = TrialDraft.__table__
    values = {"trial_ref": step.ref, "seq": body.seq, "saved_at": utcnow(),
              "data": body.model_dump(exclude={"trial_id", "seq"})}
    conn = db.connection()
    newer = upsert(conn, table).values(participant_id=participant.id, **values)
    try:
        stored = conn.execute(newer.on_conflict_do_update(
            index_elements=[table.c.participant_id], set_=values,
            where=or_(table.c.trial_ref != step.ref, table.c.seq < body.seq))
            .returning(table.c.seq)).scalar()
        if stored is None:  # a newer save of this trial is stored: it stays
            stored = conn.execute(select(table.c.seq).where(
                table.c.participant_id == participant.id)).scalar_one()
        db.commit()
    except BaseException:
        db.rollback()
        raise
    return stored


def check_shape(ctx: StudyContext, step: TrialStep, body: DraftSave) -> None:
    """The draft fits the trial: a list of clicks per start state, at most the steps to
    predict each, a time (and, when sent, an input device) per click, and a start state that
    exists (422 naming the field)."""
    states = len(ctx.bank.by_id[step.trial_id].start_states)
    steps = ctx.bank.data.steps_to_predict
    if len(body.points) != states or len(body.click_times_ms) != states:
        raise Refused(422, f"points: one list of clicks per start state ({states}) is needed, "
                           "also in click_times_ms")
    for i, (points, times) in enumerate(zip(body.points, body.click_times_ms, strict=True)):
        if len(points) > steps or len(times) != len(points):
            raise Refused(422, f"points.{i}: at most {steps} clicks, each with its time in "
                               f"click_times_ms.{i}")
    if body.click_inputs is not None:
        check_click_inputs(body.points, body.click_inputs)
    if body.index >= states:
        raise Refused(422, f"index: the trial has {states} start states")


def check_click_inputs(points: list[list], inputs: list[list]) -> None:
    """One input device per click, start state by start state (422 naming click_inputs)."""
    if len(inputs) != len(points):
        raise Refused(422, f"click_inputs: one list per start state ({len(points)}) is needed")
    for i, (clicks, devices) in enumerate(zip(points, inputs, strict=True)):
        if len(devices) != len(clicks):
            raise Refused(422, f"click_inputs.{i}: one input per click of points.{i} "
                               f"({len(clicks)}), got {len(devices)}")


def current_draft(db: Session, participant: Participant) -> dict | None:
    """The draft of the trial the participant is at (with its `seq`), or None (read in the
    caller's transaction)."""
    step = current_step(participant)
    if not isinstance(step, TrialStep):
        return None
    row = db.execute(select(TrialDraft.seq, TrialDraft.data).where(
        TrialDraft.participant_id == participant.id, TrialDraft.trial_ref == step.ref)).first()
    return None if row is None else {**row.data, "seq": row.seq}


def discard_draft(db: Session, participant: Participant) -> None:
    """Delete the session's draft (inside the caller's transaction: the trial it belonged to
    is being stored)."""
    db.execute(delete(TrialDraft.__table__).where(
        TrialDraft.participant_id == participant.id))
