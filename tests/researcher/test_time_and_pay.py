"""The dashboard's time and pay: the advertised time and pay from the estimate, the finished
sessions' median duration (by the server's clock) and the hourly pay it really earns, and a flag
when the median is more than 10% over the advertised time."""

from datetime import timedelta

import pytest
from sqlalchemy import update

from app.server.storage.tables import Participant
from tests.server.flow import ADMIN, at_first_trial


def time_and_pay(client, study_id: str) -> dict:
    r = client.get("/api/researcher/dashboard", params={"study_id": study_id}, headers=ADMIN)
    assert r.status_code == 200, r.text
    return r.json()["time_and_pay"]


def last_for(client, token: str, minutes: float) -> None:
    """Make the finished session `token` have lasted `minutes` (start moved back)."""
    with client.app.state.engine.begin() as conn:
        ended = conn.execute(Participant.__table__.select().where(
            Participant.session_token == token)).one().ended_at
        conn.execute(update(Participant.__table__).where(Participant.session_token == token)
                     .values(created_at=ended - timedelta(minutes=minutes)))


@pytest.fixture
def advert(client, small_study):
    return client.app.state.studies[small_study.study_id].estimate().advert


def test_before_anyone_finishes_it_states_the_advert_only(client, small_study, advert):
    shown = time_and_pay(client, small_study.study_id)
    assert shown["advertised_min"] == advert.minutes and shown["pay"] == advert.pay
    assert shown["median_min"] is None and not shown["overrun"] and shown["sessions"] == 0


def test_the_median_within_ten_percent_is_not_flagged(client, small_study, bank, advert):
    tokens = []
    for _ in range(3):
        p = at_first_trial(client, small_study.study_id)
        p.finish(bank)
        tokens.append(p.token)
    at_first_trial(client, small_study.study_id)  # unfinished: not in the median
    for token, minutes in zip(tokens, (0.5, 1.08, 3.0), strict=True):
        last_for(client, token, minutes * advert.minutes)
    shown = time_and_pay(client, small_study.study_id)
    assert shown["sessions"] == 3 and shown["who"] == "participants"
    assert shown["median_min"] == pytest.approx(1.08 * advert.minutes, abs=0.05)
    assert not shown["overrun"] and shown["flag"] == ""
    hourly = advert.pay_amount / (1.08 * advert.minutes / 60)
    assert shown["effective_hourly"] == f"{advert.currency} {hourly:.2f}"


def test_a_median_over_ten_percent_is_flagged_with_the_underpaid_rate(client, small_study, bank,
                                                                      advert):
    p = at_first_trial(client, small_study.study_id)
    p.finish(bank)
    last_for(client, p.token, 1.5 * advert.minutes)
    shown = time_and_pay(client, small_study.study_id)
    assert shown["overrun"] and "50% over the advertised" in shown["flag"]
    hourly = advert.pay_amount / (1.5 * advert.minutes / 60)
    assert shown["effective_hourly"] == f"{advert.currency} {hourly:.2f}"
