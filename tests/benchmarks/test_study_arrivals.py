"""The whole-flow arrivals benchmark (benchmarks/study_arrivals.py) runs every phase of the
served paper study, and fails loudly on a phase it cannot answer."""

import asyncio

import pytest

from app.server.flow.plan import Phase
from benchmarks import study_arrivals
from benchmarks.study_arrivals import (
    HANDLERS,
    ROUTES,
    UnansweredPhase,
    check_phases,
    run_cohort,
    study_without_cap,
)
from tests.conftest import free_port, start_server, stop_server

PARTICIPANTS = 3
THINK_SCALE = 0.001  # a participant's ~40 minutes of thinking in ~2.4 s
DONE_WITHIN_S = 300  # a bound for a stuck run, not a speed test (the machine may be busy)


@pytest.fixture(scope="module")
def paper_server(tmp_path_factory):
    """The paper study served from its shipped bundle on a fresh SQLite file; its port."""
    tmp_path = tmp_path_factory.mktemp("arrivals")
    study = study_without_cap(tmp_path)
    port = free_port()
    proc = start_server(study, f"sqlite:///{tmp_path / 'study.db'}", port,
                        log=tmp_path / "server.log")
    yield port
    stop_server(proc)


@pytest.mark.slow
def test_every_participant_reaches_done_through_every_phase(paper_server):
    step = asyncio.run(run_cohort(paper_server, PARTICIPANTS, rate=5, think_scale=THINK_SCALE,
                                  timeout_s=DONE_WITHIN_S))
    people = step.crowd.people
    assert len(people) == PARTICIPANTS
    assert [p.refused for p in people] == [[]] * PARTICIPANTS
    for person in people:
        assert person.phases[-1] == Phase.DONE
        assert set(person.phases) == {phase.value for phase in Phase}
    # every route the flow uses was measured, the per-click drafts and heartbeats among them
    assert {route for route in ROUTES if step.stats.get(route)} == set(ROUTES)
    trials = sum(p.phases.count(Phase.TRIAL) + p.phases.count(Phase.PRACTICE) for p in people)
    assert step.stats["PUT draft"][0] > 15 * trials  # at least a draft per click (5 x 3 a trial)
    assert step.stats["POST tab"][0] > PARTICIPANTS  # heartbeats after each tab's claim


@pytest.mark.slow
def test_a_phase_the_benchmark_cannot_answer_fails_the_run_naming_it(paper_server):
    without_intro = {p: h for p, h in HANDLERS.items() if p != Phase.WORLD_INTRO}
    with pytest.raises(UnansweredPhase, match="phase world_intro"):
        asyncio.run(run_cohort(paper_server, 2, rate=5, think_scale=THINK_SCALE,
                               timeout_s=DONE_WITHIN_S, handlers=without_intro))


def test_a_phase_of_the_plan_without_a_handler_stops_the_command_before_it_runs(monkeypatch):
    check_phases(HANDLERS)  # today every phase is answered
    monkeypatch.delitem(HANDLERS, Phase.PRACTICE_OVER)
    with pytest.raises(SystemExit) as stopped:
        study_arrivals.main(["--participants", "1"])
    assert "phase practice_over" in str(stopped.value.code)
