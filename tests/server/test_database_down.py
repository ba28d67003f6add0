"""While the database cannot be reached, every route answers 503 with Retry-After, no trace."""

import logging
import shutil

from tests.server.flow import ADMIN, Participant, make_client, new_id, prolific


def test_an_unreachable_database_gets_a_503_with_retry_after(small_study, tmp_path, caplog):
    folder = tmp_path / "db"
    with make_client(small_study, f"sqlite:///{folder / 'study.db'}") as client:
        p = Participant(client, small_study.study_id)
        p.start()
        assert p.status == 201
        client.app.state.engine.dispose()  # no pooled connection outlives the file
        shutil.rmtree(folder)  # SQLite cannot open (nor create) the file any more
        with caplog.at_level(logging.WARNING):
            answers = [p.get("state"),
                       client.post("/api/sessions", json={"study_id": small_study.study_id,
                                                          "recruitment": prolific(new_id())}),
                       client.get(f"/api/researcher/summary?study_id={small_study.study_id}",
                                  headers=ADMIN)]
        folder.mkdir()  # the lifespan's shutdown finds its folder again
    for r in answers:
        assert r.status_code == 503, r.text
        assert r.headers["retry-after"] == "5"
        assert r.json()["detail"] == "database: unavailable, try again shortly"
    records = [r for r in caplog.records if "database" in r.getMessage()]
    assert len(records) >= len(answers) and not any(r.exc_info for r in records)
