"""A session start takes no lock (sessions.py), and what must be exact stays exact when many
requests reach the database at the same moment (threads, each with its own connection, as
several workers would): one session per external id (the live index), and the study's cap
of running sessions (decided at consent, under the study's lock)."""

import threading
import uuid
from concurrent.futures import ThreadPoolExecutor

from sqlalchemy import func, select
from sqlmodel import Session

from app.server.flow import sessions
from app.server.schemas import ConsentCreate, SessionCreate
from app.server.storage import crud
from app.server.storage.tables import Participant
from app.study.errors import Refused
from tests.server.flow import Participant as Person
from tests.server.flow import prolific, with_cap

AT_ONCE = 8
CAP = 3


def all_at_once(work, n: int = AT_ONCE) -> list:
    """`work(i)` in n threads released together; their results."""
    gate = threading.Barrier(n)

    def one(i: int):
        gate.wait()
        return work(i)

    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(one, range(n)))


def test_one_external_id_started_at_once_gets_one_session(client, small_study):
    sid, engine = small_study.study_id, client.app.state.engine
    ctx = client.app.state.studies[sid]
    body = SessionCreate(study_id=sid, recruitment=prolific("at-once"))

    def start(_: int) -> tuple[str, bool]:
        with Session(engine, expire_on_commit=False) as db:
            participant, resumed = sessions.start_session(db, ctx, body)
            return participant.session_token, resumed

    answers = all_at_once(start)
    assert sorted(resumed for _, resumed in answers) == [False] + [True] * (AT_ONCE - 1)
    assert len({token for token, _ in answers}) == 1
    with Session(engine) as db:
        assert db.execute(select(func.count()).select_from(Participant)).scalar() == 1


def test_consents_at_once_take_exactly_the_cap(client, small_study):
    sid, engine = small_study.study_id, client.app.state.engine
    with_cap(client, sid, per_target=1, target=CAP)
    ctx = client.app.state.studies[sid]
    people = [Person(client, sid) for _ in range(AT_ONCE)]
    for person in people:
        person.start()
        assert person.status == 201  # a start takes no place: all are let in

    def consent(i: int) -> int:
        with Session(engine, expire_on_commit=False) as db:
            participant = sessions.participant_by_token(db, people[i].token)
            body = ConsentCreate(submission_id=uuid.uuid4(), agree=True)
            try:
                crud.record_consent(db, ctx, participant, body)
            except Refused as refused:
                return refused.status
            return 200

    assert sorted(all_at_once(consent)) == [200] * CAP + [503] * (AT_ONCE - CAP)
    with Session(engine) as db:
        counted = select(func.count()).where(Participant.counted.is_(True))
        assert db.execute(counted).scalar() == CAP
