"""Limits that fit real networks: a classroom of 30 behind one address, each participant's page
starting, consenting and answering a trial against a real server at the default rate limits,
meets no 429 (issue 32 item 4)."""

import asyncio

from app.settings import Settings
from tests.conftest import free_port, patience, start_server
from tests.server.classroom import classroom

CLASS_SIZE = 30


def test_a_classroom_behind_one_address_answers_a_trial_without_a_429(small_study, tmp_path):
    defaults = Settings()
    port = free_port()
    proc = start_server(small_study, f"sqlite:///{tmp_path / 'class.db'}", port,
                        log=tmp_path / "server.log",
                        TOMSTUDY_RATE_LIMIT_STARTS=defaults.rate_limit_starts,
                        TOMSTUDY_RATE_LIMIT_REQUESTS=defaults.rate_limit_requests)
    try:
        pupils = asyncio.run(classroom(f"http://127.0.0.1:{port}", small_study.study_id,
                                       CLASS_SIZE))
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))
    assert sum(p.answered for p in pupils) == CLASS_SIZE
    assert [r for p in pupils for r in p.refused] == []
    assert min(p.requests for p in pupils) >= 20  # the page's traffic, not a shortcut
