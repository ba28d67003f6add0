"""One live browser tab per session: another tab is told, and takes over only when asked.

A page claims the session for its tab when it loads (`opened`) and then every HEARTBEAT_S.
While another tab was heard from within TAB_ALIVE_S, a claim is refused (409 with a notice
that offers to continue here) unless the person chose to take over. Writes that name their
tab (header X-Tab-Id) are refused once another tab is live, so the tab left behind learns
why its answers are not taken instead of racing the other one; API clients and bots name
no tab and are not checked. Each page that opens after consent is an event (`page_opened`,
or `tab_takeover` when it took the session from a live tab) with the trial it opened on and
the clicks its draft restored, so the events export shows every reload and resume.
"""

from datetime import timedelta

from sqlalchemy import update
from sqlmodel import Session

from app.server.flow import notices, telemetry
from app.server.flow.drafts import current_draft
from app.server.flow.plan import TrialStep, current_step
from app.server.flow.sessions import as_utc
from app.server.schemas import PAGE_OPENED, TAB_TAKEOVER, TabClaim, TabRelease
from app.server.storage.tables import Participant, keep_loaded, utcnow
from app.study.errors import Refused

TAB_HEADER = "X-Tab-Id"
HEARTBEAT_S = 10  # the live page says it is still there this often (handed to the page)
TAB_ALIVE_S = 30  # a live tab not heard from for this long is gone: another may claim


def claim_tab(db: Session, participant: Participant, body: TabClaim) -> None:
    """Make `body.tab_id` the live tab (409 while another is alive, unless a takeover)."""
    held_by = participant.live_tab
    taken_over = held_by not in (None, body.tab_id) and _alive(participant)
    if taken_over and not body.takeover:
        raise Refused(409, "tab: this session is open in another tab or window; continue "
                           "there, or claim it with takeover", notices.open_in_another_tab())
    table = Participant.__table__
    held = table.c.live_tab.is_(None) if held_by is None else table.c.live_tab == held_by
    now = utcnow()
    try:
        moved = db.execute(update(table).where(table.c.id == participant.id, held)
                           .values(live_tab=body.tab_id, live_tab_seen_at=now))
        if moved.rowcount != 1:
            raise Refused(409, "tab: another tab claimed this session at the same moment; "
                               "try again", notices.open_in_another_tab())
        keep_loaded(participant, live_tab=body.tab_id, live_tab_seen_at=now)
        if body.opened:
            telemetry.record_server_event(
                db, participant, TAB_TAKEOVER if taken_over else PAGE_OPENED,
                body.t_client_ms, opened_at(participant, current_draft(db, participant)))
        db.commit()
    except BaseException:
        db.rollback()
        raise


def opened_at(participant: Participant, draft: dict | None) -> dict:
    """Where a page opened: the trial on screen ('' between trials), the start state its
    draft resumes (-1 without one) and the clicks the draft restored."""
    step = current_step(participant)
    ref = step.ref if isinstance(step, TrialStep) else ""
    if draft is None:
        return {"trial_id": ref, "start_index": -1, "clicks": 0}
    return {"trial_id": ref, "start_index": draft["index"],
            "clicks": sum(len(points) for points in draft["points"])}


def release_tab(db: Session, participant: Participant, body: TabRelease) -> None:
    """The live tab is closing: another may claim the session without being asked."""
    table = Participant.__table__
    db.execute(update(table).where(table.c.id == participant.id,
                                   table.c.live_tab == body.tab_id)
               .values(live_tab_seen_at=None))
    db.commit()


def check_live_tab(participant: Participant, tab_id: str | None) -> None:
    """409 if a write comes from a tab other than the session's live one."""
    if tab_id and participant.live_tab and participant.live_tab != tab_id:
        raise Refused(409, "tab: this session continues in another tab; this tab's answer "
                           "was not stored", notices.open_in_another_tab())


def _alive(participant: Participant) -> bool:
    seen = participant.live_tab_seen_at
    return seen is not None and utcnow() - as_utc(seen) < timedelta(seconds=TAB_ALIVE_S)
