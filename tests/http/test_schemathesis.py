"""Schemathesis against the study app, with every check: each answer is one the schema declares.

Valid cases sometimes carry a real session token (the X-Session-Token header, at each
phase), the study id, Prolific parameters, the preview key and the researcher's token
instead of drawn ones, so requests also get past 404, 403 and 401. Rate limits are off
here (tests/http/test_traffic.py tests them); a replaced session's 410 is declared. The
in-suite run is small; the issue's must-show run is the same test with more examples per
operation and a floor on the total: `make fuzz` (SCHEMATHESIS_MAX_EXAMPLES=600,
SCHEMATHESIS_MIN_CASES=5000).
"""

import os
import zlib

import pytest
import schemathesis
from fastapi import FastAPI
from hypothesis import HealthCheck, settings
from schemathesis.config import SchemathesisConfig

from app.main import create_app
from app.server.flow.plan import PART_PHASES, TRIAL_PHASES, Phase
from app.server.flow.recruitment import preview_key
from app.settings import Settings
from tests.conftest import local_client
from tests.server.flow import ADMIN, TOKEN, Participant, new_id, prolific

# one generated item per operation, all under one node id: pytest-xdist would run only the
# first (test_cases_ran_on_every_operation notices), so `make test` runs this file alone
pytestmark = pytest.mark.serial

MAX_EXAMPLES = int(os.environ.get("SCHEMATHESIS_MAX_EXAMPLES", "15"))
MIN_CASES = int(os.environ.get("SCHEMATHESIS_MIN_CASES", "100"))
# A session write valid per the schema may still break a study rule the schema does not
# state (422): clicks outside the scene or out of reach, a draft that does not fit its
# trial, answers to other questions, telemetry past its cap, a submission_id reused for
# another request; or exceed 64 KiB.
STUDY_RULES = ["2xx", "3xx", "401", "403", "404", "409", "413", "422"]
# schemathesis' list of statuses that reject invalid data, plus 413: a body over 64 KiB
REJECTIONS = ["400", "401", "403", "404", "405", "406", "409", "413", "415", "422", "428",
              "429", "5xx"]
CONFIG = SchemathesisConfig.from_dict({
    "checks": {"negative_data_rejection": {"expected-statuses": REJECTIONS}},
    "operations": [{
        "include-path-regex":
            "/(consent|decline|screen-out|instructions|continue|draft|predictions|survey|events)$",
        "checks": {"positive_data_acceptance": {"expected-statuses": STUDY_RULES}}}]})
# The schema does not depend on a study, so it is read at import from an app that never
# starts; the requests go to the small study's app (`study_app`).
schema = schemathesis.openapi.from_dict(
    create_app(Settings(production=False, admin_token=TOKEN)).openapi(), config=CONFIG)
cases_run: list[str] = []


@pytest.fixture(scope="module")
def study_app(small_study, tmp_path_factory) -> FastAPI:
    """The small study's app on a fresh SQLite file."""
    root = tmp_path_factory.mktemp("schemathesis")
    return create_app(small_study.settings(f"sqlite:///{root / 'study.db'}", production=False),
                      [small_study.study_id])


@pytest.fixture(scope="module")
def real_values(study_app, small_study) -> dict[str, list]:
    """Real values to swap in for drawn ones, by key (None: keep the drawn value)."""
    tokens = []
    with local_client(study_app) as client:
        for phase in (Phase.CONSENT, Phase.INSTRUCTIONS, Phase.WORLD_INTRO, Phase.PRACTICE,
                      Phase.PRACTICE_OVER, Phase.SURVEY, Phase.DONE):
            tokens.append(session_at(client, small_study.study_id, phase))
    people = [prolific(f"fuzz-{i}") for i in range(20)]  # a new session, then resumes
    return {"X-Session-Token": [None, *tokens], "study_id": [None, small_study.study_id],
            "authorization": [None, ADMIN["Authorization"]], "recruitment": [None, *people],
            "preview": [None, preview_key(TOKEN, small_study.study_id)]}


def session_at(client, study_id: str, phase: Phase) -> str:
    """The token of a new anonymous session moved on to `phase`."""
    p = Participant(client, study_id)
    p.start()
    while (now := p.state()["phase"]) != phase:
        if now == Phase.CONSENT:
            p.consent()
        elif now == Phase.INSTRUCTIONS:
            p.post("instructions", {"submission_id": new_id()})
        elif now in PART_PHASES:
            p.post("continue", {"submission_id": new_id(), "phase": now})
        elif now in TRIAL_PHASES:
            p.answer_trial()
        else:
            p.survey()
    return p.token


def pick(seed, choices: list):
    """One of `choices`, chosen by `seed` (a drawn value, so a failing case replays the same)."""
    return choices[zlib.crc32(repr(seed).encode()) % len(choices)]


def aim_at_real_values(case, real: dict[str, list]) -> None:
    """In a valid case, swap some drawn values for real ones to get past 404, 403 and 401.

    Invalid cases keep their values: a swap could make them valid and the request accepted.
    """
    if case.meta is None or not case.meta.generation.mode.is_positive:
        return
    if case.path.startswith("/api/researcher/"):
        bearer = pick((case.headers, case.query), real["authorization"])
        if bearer:
            case.headers = case.headers or {}
            case.headers["authorization"] = bearer
    for values, key in ((case.headers, "X-Session-Token"), (case.query, "study_id"),
                        (case.body, "study_id"), (case.body, "recruitment"),
                        (case.body, "preview")):
        if isinstance(values, dict) and key in values:
            values[key] = pick((key, values[key]), real[key]) or values[key]


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
def test_every_answer_is_declared_in_the_schema(case, study_app, real_values):
    aim_at_real_values(case, real_values)
    cases_run.append(case.operation.label)
    # a loopback name: a public one in TOMSTUDY_ALLOWED_HOSTS would make the app production
    case.call_and_validate(app=study_app, base_url="http://localhost")


def test_cases_ran_on_every_operation():
    """After the schemathesis test (file order): every operation had cases, MIN_CASES in all."""
    if not cases_run:
        pytest.skip("counts the cases of test_every_answer_is_declared_in_the_schema")
    operations = {op.ok().label for op in schema.get_all_operations()}
    print(f"\nschemathesis: {len(cases_run)} cases on {len(operations)} operations, at most "
          f"{MAX_EXAMPLES} fuzzed examples each (SCHEMATHESIS_MAX_EXAMPLES)")
    assert set(cases_run) == operations
    assert len(cases_run) >= MIN_CASES
