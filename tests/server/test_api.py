"""The participant and researcher API, on SQLite and on PostgreSQL (same tests, both backends)."""

import io
import json
import math

import pandas as pd
import pytest
from sqlalchemy import select

from analysis.load import load_csv
from app.configio import load_yaml_model
from app.server.flow.plan import Phase
from app.server.storage.tables import PredictionRow
from app.study.config import StudyConfig
from tests.server.flow import (
    ADMIN,
    Participant,
    at_first_trial,
    hex24,
    new_id,
    prediction_body,
    prolific,
)


@pytest.fixture(scope="module")
def per_trial(small_study) -> tuple[int, int]:
    """(start states, steps to predict) per trial, as the small study's config sets them."""
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    return cfg.start_states, cfg.steps_to_predict


def test_whole_session_stores_every_prediction_beside_the_models(codes, client, small_study,
                                                                  bank, per_trial):
    p = Participant(client, small_study.study_id)
    body = p.start(**prolific("alice"))
    assert p.status == 201 and body["resumed"] is False
    assert isinstance(body["participant_id"], str) and len(body["participant_id"]) == 16
    assert p.state()["phase"] == Phase.CONSENT
    state = p.pass_intro()
    assert state["phase"] == Phase.PRACTICE
    trial = state["step"]
    k, n = per_trial
    assert len(trial["examples"]) == 4 and len(trial["start_states"]) == k
    assert all("start_kind" not in s for s in trial["start_states"])
    assert "attention_check" not in trial and "clip_sha256" not in trial
    assert trial["trial_id"] not in bank  # an opaque per-session id, not the bank's
    assert 5 <= len(trial["segment"]["positions"]) - 1 <= 7
    assert "predictions" not in trial and "policy_actions" not in trial
    done = p.finish(bank)
    assert done["phase"] == Phase.DONE and done["step"]["completion_code"] == codes["completed"]
    assert done["step"]["redirect_url"].endswith(f"cc={codes['completed']}")
    total = done["progress"]["total"]
    assert total == 2 * (1 + 3 + 1)  # per world: 1 practice, 3 trials and 1 attention check

    r = client.get(f"/api/researcher/export.csv?study_id={small_study.study_id}", headers=ADMIN)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    frame = pd.read_csv(io.StringIO(r.text))
    assert len(frame) == total * k * n
    assert frame["completed"].dtype == bool and frame["attention_passed"].all()
    assert frame["ours_code"].dtype.kind == "i" and frame["participant_vx"].dtype.kind == "f"
    assert frame.groupby("trial_id").size().eq(k * n).all()
    assert frame["is_practice"].sum() == 2 * k * n and frame["attention_check"].sum() == 2 * k * n
    for (trial_id, start), kinds in frame.groupby(["trial_id", "start_index"])["start_kind"]:
        assert set(kinds) == {bank[trial_id]["start_states"][start]["start_kind"]}
    arms = frame.fillna({"arm": ""}).groupby("trial_id")["arm"].agg(set)
    assert all(got == {bank[tid]["arm"]} for tid, got in arms.items())
    assert {bank[tid]["arm"] for tid in arms.index} == {"random", "models_disagree", ""}
    row = frame.iloc[0]
    primary = bank[row["trial_id"]]["predictions"]["ours"][0]  # the family's first seed
    stored = bank[row["trial_id"]]
    assert row["ours_sha256"] == primary["content_hash"] and primary["seed"] == 0
    assert row["ours_code"] == primary["code"]
    assert math.isclose(row["ours_vx"], primary["actions"][0][0][0], abs_tol=1e-4)
    assert math.isclose(row["policy_vy"], stored["policy_actions"][0][0][1], abs_tol=1e-9)
    assert row["clip_sha256"] == stored["clip_sha256"]
    dt = json.loads(json.dumps(trial["dt_s"]))
    first = frame[(frame.trial_id == row.trial_id) & (frame.start_index == 0)]
    moved = first.iloc[0]["participant_click_x"] - first.iloc[0]["start_x"]
    assert math.isclose(first.iloc[0]["participant_vx"], moved / dt, rel_tol=1e-6)
    assert (frame["trial_duration_ms"] == 8000).all()

    summary = client.get(f"/api/researcher/summary?study_id={small_study.study_id}",
                         headers=ADMIN).json()
    assert summary["progress"]["completed"] == 1
    assert summary["alignment_error"]["exclusions"]["participants_kept"] == 1
    for world in ("highway", "obstacle"):
        means = summary["alignment_error"]["kept"][world]
        assert all(0 <= means[m] <= 2 for m in ("ours", "vae", "cv", "policy"))


def test_refresh_resumes_and_an_external_id_takes_part_once(client, small_study):
    p = at_first_trial(client, small_study.study_id, **prolific("w1"))
    p.answer_trial()
    before = p.state()
    again = Participant(client, small_study.study_id)
    body = again.start(**prolific("w1"))
    assert again.status == 200 and body["resumed"] and again.token == p.token
    assert again.state() == before
    p.finish()
    late = Participant(client, small_study.study_id)
    late.start(**dict(prolific("w1"), SESSION_ID="another-attempt"))
    assert late.status == 409


def test_knowing_a_participant_id_alone_does_not_open_their_session(client, small_study):
    params = prolific("pid-9")
    owner = at_first_trial(client, small_study.study_id, **params)
    intruder = Participant(client, small_study.study_id)
    body = intruder.start(**dict(params, SESSION_ID="guess"))
    assert intruder.status == 409 and "SESSION_ID" in body["detail"]
    assert intruder.token != owner.token
    same = Participant(client, small_study.study_id)
    same.start(**params)
    assert same.status == 200 and same.token == owner.token


def test_retried_submission_is_stored_once_with_the_same_answer(client, small_study, per_trial):
    p = at_first_trial(client, small_study.study_id, **prolific("retry"))
    body = prediction_body(p.state()["step"])
    first = p.post("predictions", body)
    second = p.post("predictions", body)
    assert (first.status_code, second.status_code) == (201, 200)
    assert first.json() == second.json()
    csv = client.get(f"/api/researcher/export.csv?study_id={small_study.study_id}",
                     headers=ADMIN).text
    assert len(pd.read_csv(io.StringIO(csv))) == per_trial[0] * per_trial[1]
    consent_again = p.post("consent", {"submission_id": new_id(), "agree": True})
    assert consent_again.status_code == 409


def test_each_clicks_input_device_is_stored_and_exported(client, small_study, per_trial):
    k, n = per_trial
    p = at_first_trial(client, small_study.study_id)
    body = prediction_body(p.state()["step"])
    pen = [["mouse", "pen", "mouse"], *body["click_inputs"][1:]]
    r = p.post("predictions", dict(body, submission_id=new_id(), click_inputs=pen))
    assert r.status_code == 422 and r.json()["message"] == \
        "click_inputs.0.1: Input should be 'mouse', 'keyboard' or 'touch'", r.text
    r = p.post("predictions", dict(body, submission_id=new_id(),
                                   click_inputs=body["click_inputs"][:-1]))
    assert r.status_code == 422 and r.json()["detail"].startswith(
        f"click_inputs: expected {k} start states"), r.text
    devices = [[("mouse", "keyboard", "touch")[(i + j) % 3] for j in range(n)] for i in range(k)]
    assert p.post("predictions", dict(body, click_inputs=devices)).status_code == 201
    older = prediction_body(p.pass_screens()["step"])  # a client that predates the field
    del older["click_inputs"]
    assert p.post("predictions", older).status_code == 201

    with client.app.state.engine.connect() as conn:
        stored = conn.execute(select(PredictionRow.submission_id, PredictionRow.start_index,
                                     PredictionRow.step, PredictionRow.click_input)).all()
    assert [d for s, _, _, d in stored if s == older["submission_id"]] == [None] * k * n
    assert {(i, j): d for s, i, j, d in stored if s == body["submission_id"]} == {
        (i, j): devices[i][j] for i in range(k) for j in range(n)}
    csv = client.get(f"/api/researcher/export.csv?study_id={small_study.study_id}",
                     headers=ADMIN).text
    frame = load_csv(io.StringIO(csv))
    by_submission = frame.groupby("submission_id")["click_input"].agg(list)
    assert by_submission[body["submission_id"]] == [d for row in devices for d in row]
    assert by_submission[older["submission_id"]] == [""] * k * n  # unknown


def test_events_are_stored_once(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    events = [{"submission_id": new_id(), "kind": "clip_finished", "t_client_ms": 10.0 * i,
               "data": {"trial_id": "t", "replays": i}} for i in range(3)]
    assert p.post("events", {"events": events}).json() == {"stored": 3}
    assert p.post("events", {"events": events}).json() == {"stored": 0}
    assert p.post("events", {"events": events[:1] * 101}).status_code == 422


def test_world_orders_and_trials_are_assigned_in_balance(client, small_study, bank):
    for i in range(4):  # two completions, two sessions still running
        p = at_first_trial(client, small_study.study_id, **prolific(f"bal{i}"))
        if i < 2:
            p.finish(bank)
    csv = client.get(f"/api/researcher/export.csv?study_id={small_study.study_id}",
                     headers=ADMIN).text
    frame = pd.read_csv(io.StringIO(csv))
    first_world = frame[frame.world_position == 0].groupby("participant_id")["world"].first()
    assert sorted(first_world) == ["highway", "obstacle"]  # the two completions split
    summary = client.get(f"/api/researcher/summary?study_id={small_study.study_id}",
                         headers=ADMIN).json()
    counts = {k: v["completed"] + v["in_progress"]
              for k, v in summary["progress"]["world_orders"].items()}
    assert sorted(counts.values()) == [2, 2]
    main = frame[~frame.is_practice & ~frame.attention_check]
    exposure = main.drop_duplicates(["participant_id", "trial_id"]).groupby("trial_id").size()
    per_world = {w: exposure[[t for t in exposure.index if t.startswith(w)]]
                 for w in ("highway", "obstacle")}
    for world, counts in per_world.items():
        # 2 completions x 3 trials over a pool of 5: least-exposed first -> counts 1 or 2
        assert counts.sum() == 6 and counts.max() - counts.min() <= 1, world


def test_excluded_completions_do_not_count_for_balance(client, small_study, bank):
    from sqlmodel import Session, select

    from app.server.flow import balance
    from app.server.storage.tables import Participant as Row

    valid = at_first_trial(client, small_study.study_id, **prolific("valid"))
    valid.finish(bank)
    hasty = at_first_trial(client, small_study.study_id, **prolific("hasty"))
    hasty.finish(bank, duration_ms=1000)
    careless = at_first_trial(client, small_study.study_id, **prolific("careless"))
    careless.finish(None)  # straight clicks ignore the attention checks' obvious answer
    running = at_first_trial(client, small_study.study_id, **prolific("running"))
    running.answer_trial()
    ctx = client.app.state.studies[small_study.study_id]
    names = {hex24(n): n for n in ("valid", "hasty", "careless", "running")}
    with Session(client.app.state.engine) as db:
        counted = {names[p.external_id] for p in db.exec(select(Row).where(Row.counted))}
        assert balance.recount(db, ctx) == {k: v for k, v in balance.read_counts(
            db, ctx.study_id).items() if v}
    assert "valid" in counted and "running" in counted and "hasty" not in counted
    summary = client.get(f"/api/researcher/summary?study_id={small_study.study_id}",
                         headers=ADMIN).json()
    excluded = summary["alignment_error"]["exclusions"]
    assert excluded["excluded_too_fast"] == 1 and excluded["excluded_incomplete"] == 1
    assert excluded["participants_kept"] == 2 - ("careless" not in counted)
    assert running.pass_screens()["phase"] == Phase.TRIAL


# ---------------------------------------------------------------- refusals

def bad_prediction_cases(trial: dict) -> dict:
    """name -> (body, expected status, text the message must contain)."""
    good = prediction_body(trial)
    b = trial["scene"]["bounds"]
    start = trial["start_states"][0]["robot"]

    def with_points(fn):
        body = json.loads(json.dumps(good))
        body["submission_id"] = new_id()
        fn(body["points"])
        return body

    far = [b["x_max_m"] + 5.0, start[1]]
    k = len(trial["start_states"])
    last = trial["start_states"][k - 1]["robot"]
    mid_x = (b["x_min_m"] + b["x_max_m"]) / 2
    return {
        "wrong count of start states": (with_points(lambda p: p.pop()), 422,
                                        f"points: expected {k} start states"),
        "wrong count of steps": (with_points(lambda p: p[2].pop()), 422, "points.2: expected 3"),
        "outside the scene": (with_points(lambda p: p[0].__setitem__(2, far)), 422,
                              "points.0.2"),
        "zero-length move": (with_points(lambda p: p[1].__setitem__(0, trial["start_states"][1]
                                                                  ["robot"])), 422, "points.1.0"),
        "too-short move": (with_points(lambda p: p[1].__setitem__(1, [
            p[1][0][0] + trial["min_step_m"] / 3, p[1][0][1]])), 422, "shorter than"),
        "too-long move": (with_points(lambda p: p[k - 1].__setitem__(0, [
            last[0] + 1.5 * trial["max_step_m"] * (1 if last[0] < mid_x else -1), last[1]])), 422,
                          "longer than"),
    }


def test_bad_predictions_get_a_4xx_naming_the_field(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]
    for name, (body, status, needle) in bad_prediction_cases(trial).items():
        r = p.post("predictions", body)
        assert r.status_code == status, (name, r.text)
        assert needle in r.json()["detail"], (name, r.text)
    # NaN / Infinity: Python's json accepts these literals; the server must not
    last = len(trial["start_states"]) - 1
    for literal, (i, j, k) in (("NaN", (0, 0, 0)), ("Infinity", (last, 2, 1))):
        body = prediction_body(trial)
        body["points"][i][j][k] = 123456.789  # a marker, replaced by the bare literal
        raw = json.dumps(body).replace("123456.789", literal)
        r = p.post("predictions", None, content=raw,
                   headers={"content-type": "application/json"})
        assert r.status_code == 422, r.text
        assert f"points.{i}.{j}.{k}: Input should be a finite number" in r.json()["message"]
    for unknown in (next(iter(bank)), "0123456789abcdef"):  # a bank id, someone's ref
        r = p.post("predictions", dict(prediction_body(trial), trial_id=unknown))
        assert r.status_code == 404 and r.json()["detail"].startswith("trial_id:"), r.text
    later = next(s["ref"] for s in _plan(client, p)[::-1] if "ref" in s)
    r = p.post("predictions", dict(prediction_body(trial), trial_id=later))
    assert r.status_code == 409 and "not the current trial" in r.json()["detail"]
    r = p.post("predictions", None, content=b"{" + b" " * (70 * 1024) + b"}",
               headers={"content-type": "application/json"})
    assert r.status_code == 413 and r.json()["detail"].startswith("body:")
    assert p.state()["step"]["trial_id"] == trial["trial_id"]  # nothing moved


def _plan(client, participant: Participant) -> list[dict]:
    from app.server.storage.tables import Participant as Row

    with client.app.state.engine.connect() as conn:
        return conn.execute(Row.__table__.select().where(
            Row.__table__.c.session_token == participant.token)).mappings().one()["plan"]


def test_other_bad_inputs(client, small_study):
    r = client.post("/api/sessions", json={"study_id": "nope"})
    assert r.status_code == 404 and r.json()["detail"].startswith("study_id:")
    r = client.get("/api/session/state", headers={"X-Session-Token": "not-a-token"})
    assert r.status_code == 404 and r.json()["detail"].startswith("X-Session-Token:")
    r = client.get("/api/session/state")
    assert r.status_code == 422 and "X-Session-Token" in r.json()["message"]
    p = Participant(client, small_study.study_id)
    p.start()
    r = p.post("consent", {"submission_id": new_id(), "agree": False})
    assert r.status_code == 422 and "agree" in r.json()["message"]
    r = p.post("consent", {"submission_id": "not-a-uuid", "agree": True})
    assert r.status_code == 422 and "submission_id" in r.json()["message"]
    r = p.post("survey", {"submission_id": new_id(), "answers": {}})
    assert r.status_code == 409 and r.json()["detail"].startswith("phase:")


def test_survey_answers_are_checked(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    while p.state()["phase"] != Phase.SURVEY:
        p.answer_trial(bank)
    r = p.post("survey", {"submission_id": new_id(), "answers": {"difficulty": 9}})
    assert r.status_code == 422 and r.json()["detail"].startswith("answers.difficulty")
    r = p.post("survey", {"submission_id": new_id(), "answers": {"colour": "red"}})
    assert r.status_code == 422 and r.json()["detail"].startswith("answers.colour")


def test_researcher_routes_need_the_token(client, small_study):
    path = f"/api/researcher/summary?study_id={small_study.study_id}"
    missing = client.get(path)
    assert missing.status_code == 401 and missing.json()["detail"].startswith("authorization:")
    wrong = client.get(path, headers={"Authorization": "Bearer nope"})
    assert wrong.status_code == 403
    assert client.get(path.replace("summary", "export.csv"),
                      headers={"Authorization": "Bearer nope"}).status_code == 403
    assert client.get(path, headers=ADMIN).status_code == 200


def test_pages_render(client, small_study):
    for path in ("/", f"/s/{small_study.study_id}?PROLIFIC_PID=a", "/researcher"):
        r = client.get(path)
        assert r.status_code == 200 and "<html" in r.text.lower(), path
    assert client.get("/s/unknown").status_code == 404
