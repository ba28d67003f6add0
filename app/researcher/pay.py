"""The dashboard's time and pay check: finished sessions' median duration against the time the
study advertises (app/study/estimate.py), and the hourly pay that median really earns."""

import statistics

from app.server.queries import FINISHED, Participant, StudyContext, as_utc
from app.study.consent import money

OVERRUN_LIMIT = 0.10  # a median more than 10% over the advertised time is flagged


def finished_minutes(people: list[Participant], pilot: bool) -> list[float]:
    """Minutes from start to end of every session that did every trial (replaced ones aside)."""
    return [(as_utc(p.ended_at) - as_utc(p.created_at)).total_seconds() / 60 for p in people
            if p.outcome in FINISHED and p.ended_at and p.replaced_at is None
            and p.pilot == pilot]


def time_and_pay(ctx: StudyContext, people: list[Participant]) -> dict:
    """The advertised time and pay, the finished participants' median minutes (the pilots'
    while no participant finished) and effective hourly pay, and the overrun flag."""
    found = ctx.estimate()
    advert = found.advert
    minutes, who = finished_minutes(people, pilot=False), "participants"
    if not minutes:
        minutes, who = finished_minutes(people, pilot=True), "pilots"
    out = {"advertised_min": advert.minutes, "pay": advert.pay, "hourly": advert.hourly,
           "estimate_min": round(found.median.total_min, 1),
           "slow_estimate_min": round(found.slow.total_min, 1),
           "sessions": len(minutes), "who": who, "median_min": None, "effective_hourly": None,
           "overrun": False, "flag": ""}
    if not minutes:
        return out
    median = statistics.median(minutes)
    out["median_min"] = round(median, 1)
    if advert.pay_amount:
        out["effective_hourly"] = money(advert.pay_amount / (median / 60), advert.currency)
    if median > advert.minutes * (1 + OVERRUN_LIMIT):
        out["overrun"] = True
        out["flag"] = (f"The {who}' median time, {median:.1f} min, is "
                       f"{100 * (median / advert.minutes - 1):.0f}% over the advertised "
                       f"{advert.minutes} min: they are underpaid. Raise the advertised time "
                       f"and pay on the platform, or shorten the study.")
    return out
