"""The dashboard API: sessions, versions, alignment CIs checked by scipy, trial replays."""

import hashlib
import io
import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from sqlalchemy import update

from analysis.bank import read_bank
from analysis.load import load_csv
from analysis.metrics import add_alignment_errors, apply_exclusions
from analysis.report import preregistered_primary
from analysis.seeds import seed_results
from analysis.verdicts import EXPLORATORY, primary_sentences
from app.core.contracts import COARSE_OBSERVERS
from app.server.storage.tables import Participant, TrialResponse
from app.study.config import load_study_config
from tests.server.flow import ADMIN, at_first_trial, prediction_body, straight_clicks
from tests.server.flow import Participant as Person


def dashboard(client, study_id: str, **params) -> dict:
    r = client.get("/api/researcher/dashboard", params={"study_id": study_id, **params},
                   headers=ADMIN)
    assert r.status_code == 200, r.text
    return r.json()


@pytest.fixture
def finished(client, small_study, bank) -> list[Person]:
    """Three completed participants and one that has answered its practice trial."""
    people = []
    for _ in range(3):
        p = at_first_trial(client, small_study.study_id)
        p.finish(bank)
        people.append(p)
    people.append(at_first_trial(client, small_study.study_id))
    people[-1].answer_trial(bank)
    return people


def test_dashboard_routes_need_the_token(client, small_study):
    paths = ["/api/researcher/dashboard", "/api/researcher/participants/abc/trials",
             "/api/researcher/participants/abc/trials/t"]
    for path in paths:
        params = {"study_id": small_study.study_id}
        assert client.get(path, params=params).status_code == 401
        wrong = {"Authorization": "Bearer nope"}
        assert client.get(path, params=params, headers=wrong).status_code == 403
    assert client.get(paths[1], params={"study_id": small_study.study_id},
                      headers=ADMIN).status_code == 404


def test_sessions_table_in_order_of_start_without_external_ids(client, small_study, finished):
    rows = dashboard(client, small_study.study_id)["participants"]
    assert len(rows) == 4
    assert [r["started_at"] for r in rows] == sorted(r["started_at"] for r in rows)
    assert all("external_id" not in r for r in rows)
    assert [r["status"] for r in rows] == ["ended"] * 3 + ["in_progress"]
    assert [r["outcome"] for r in rows] == ["completed"] * 3 + [None]
    checks = 2  # small_study: one attention check per world
    assert [r["attention"] for r in rows[:3]] == [{"failed": 0, "seen": checks}] * 3
    assert rows[3]["progress"]["done"] == 1
    assert rows[0]["progress"]["done"] == rows[0]["progress"]["total"] > 1
    assert all(r["config_current"] and r["bank_current"] for r in rows)
    shown = dashboard(client, small_study.study_id, external_ids=True)["participants"]
    assert all(r["external_id"] for r in shown)


def _independent_cis(csv_text: str) -> dict:
    """Per world and model: mean and scipy's t interval of per-participant mean 1 - cos."""
    rows = pd.read_csv(io.StringIO(csv_text))
    rows = rows[rows["completed"] & ~rows["is_practice"] & ~rows["attention_check"]]
    out = {}
    for model in ("ours", "vae", "cv", "policy"):
        h = rows[["participant_vx", "participant_vy"]].to_numpy()
        m = rows[[f"{model}_vx", f"{model}_vy"]].to_numpy()
        cos = (h * m).sum(1) / (np.linalg.norm(h, axis=1) * np.linalg.norm(m, axis=1))
        per = rows.assign(err=1 - cos).groupby(["world", "participant_id"])["err"].mean()
        for world, values in per.groupby(level=0):
            low, high = stats.t.interval(0.95, len(values) - 1, loc=values.mean(),
                                         scale=stats.sem(values))
            out[(world, model)] = (values.mean(), low, high, len(values))
    return out


def test_error_cis_equal_scipy_on_the_same_rows(client, small_study, finished):
    board = dashboard(client, small_study.study_id)
    csv = client.get("/api/researcher/export.csv", params={"study_id": small_study.study_id},
                     headers=ADMIN).text
    expected = _independent_cis(csv)
    worlds = board["alignment"]["worlds"]
    assert set(worlds) == {w for w, _ in expected} == {"highway", "obstacle"}
    assert len(expected) == 2 * 4  # two worlds, four models
    for (world, model), (mean, low, high, n) in expected.items():
        got = worlds[world]["models"][model]
        assert worlds[world]["n"] == n == 3
        assert got["mean"] == pytest.approx(mean, abs=1e-12)
        assert got["ci95"] == pytest.approx([low, high], abs=1e-12)
    assert board["alignment"]["exclusions"]["excluded_incomplete"] == 1
    live = dashboard(client, small_study.study_id, rules="live")["alignment"]
    assert live["exclusions"].get("excluded_incomplete", 0) == 0


def test_the_primary_verdict_in_words_is_the_reports(client, small_study, finished, tmp_path):
    """The dashboard says per world the sentence report.html's first page says, on the same
    kept rows: the export through the analysis' exclusions, seeds and primary test."""
    board = dashboard(client, small_study.study_id)["alignment"]
    csv = client.get("/api/researcher/export.csv", params={"study_id": small_study.study_id},
                     headers=ADMIN).text
    (tmp_path / "export.csv").write_text(csv)
    frame = load_csv(tmp_path / "export.csv")
    bank = read_bank(small_study.layout.bank(small_study.study_id))
    assert set(frame["bank_sha256"]) == {bank.sha256}  # every row joins every seed's answers
    config = load_study_config(small_study.settings("sqlite://"), small_study.study_id)
    kept = add_alignment_errors(apply_exclusions(frame, config.exclusions).kept)
    seeds = seed_results(kept, bank, "bank")
    primary = preregistered_primary(seeds.family_rows, config.exploratory_worlds,
                                    config.smallest_effect_of_interest, tmp_path)
    expected = primary_sentences(json.loads(json.dumps(primary, default=float)))
    assert set(expected) == {"highway", "obstacle"}
    assert board["verdicts"] == expected
    for world, sentence in board["verdicts"].items():
        exploratory = world in config.exploratory_worlds
        assert sentence.startswith(world.capitalize() + (f" ({EXPLORATORY}): " if exploratory
                                                         else ": "))
        assert "3 participants" in sentence
    live = dashboard(client, small_study.study_id, rules="live")["alignment"]["verdicts"]
    assert set(live) == {"highway", "obstacle"}


def test_field_panels_hold_each_models_top_codes(client, small_study, finished):
    fields = dashboard(client, small_study.study_id)["alignment"]["fields"]
    assert set(fields) == {"highway", "obstacle"}
    for field in fields.values():
        assert field["scene"]["bounds"] and field["arrow_m"] > 0
        assert {panel["model"] for panel in field["panels"]} == {"ours", "vae"}
        for panel in field["panels"]:
            assert panel["trials"] >= 1 and panel["states"]
            for state in panel["states"]:
                assert np.hypot(*state["human"]) == pytest.approx(1, abs=1e-3)


def test_versions_warn_when_sessions_ran_under_another_config(client, small_study, finished):
    versions = dashboard(client, small_study.study_id)["versions"]
    assert versions["warnings"] == []
    with client.app.state.engine.begin() as conn:
        conn.execute(update(Participant.__table__).where(Participant.id == 1)
                     .values(config_sha256="0" * 64))
    versions = dashboard(client, small_study.study_id)["versions"]
    assert len(versions["warnings"]) == 1 and "1 of 4 sessions" in versions["warnings"][0]
    counts = {e["sha256"]: e["sessions"] for e in versions["config"]["sessions"]}
    assert counts == {versions["config"]["loaded"]: 3, "0" * 64: 1}
    rows = dashboard(client, small_study.study_id)["participants"]
    assert sum(not r["config_current"] for r in rows) == 1


def test_replay_is_the_bank_clip_and_the_stored_clicks(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    shown = p.state()["step"]
    body = prediction_body(shown, straight_clicks(shown))
    body["history"] = [{"action": "undo", "start_index": 0, "t_ms": 900.0},
                       {"action": "reset", "start_index": 2, "t_ms": 2500.0}]
    assert p.post("predictions", body).status_code == 201
    public_id = dashboard(client, small_study.study_id)["participants"][0]["public_id"]
    base = f"/api/researcher/participants/{public_id}/trials"
    trials = client.get(base, params={"study_id": small_study.study_id}, headers=ADMIN).json()
    (trial,) = trials["trials"]
    assert trial["clicks"] == 15 and trial["history"] == 2
    r = client.get(f"{base}/{trial['trial_id']}", params={"study_id": small_study.study_id},
                   headers=ADMIN)
    assert r.status_code == 200, r.text
    replay = r.json()
    record = bank[trial["trial_id"]]
    clip = replay["trial"]
    for key in ("examples", "segment", "start_states", "scene", "dt_s"):
        assert clip[key] == shown[key]  # exactly what the participant's browser was given
    assert clip["segment"]["positions"] == record["segment"]["positions"]
    canonical = json.dumps({k: clip[k] for k in ("scene", "dt_s", "examples", "segment",
                                                 "start_states")},
                           sort_keys=True, separators=(",", ":")).encode()
    assert hashlib.sha256(canonical).hexdigest() == replay["clip_sha256"] == record["clip_sha256"]
    clicks = [[c["at"] for c in s["clicks"]] for s in replay["starts"]]
    assert clicks == body["points"]
    times = [[c["t_ms"] for c in s["clicks"]] for s in replay["starts"]]
    assert times == body["click_times_ms"]
    assert [(c["start_index"], c["step"]) for c in replay["click_order"]] == [
        (i, j) for i in range(5) for j in range(3)]
    assert replay["response"]["history"] == body["history"]
    # the canvas draws exactly `models` (replay.js has no list of its own): the coarse observers
    # too, without plug-ins
    assert replay["models"] == ["ours", "vae", "policy", *COARSE_OBSERVERS]
    assert all(set(replay["models"]) <= set(s["paths"]) & set(s["errors"])
               for s in replay["starts"])
    dt = clip["dt_s"]
    policy = np.asarray(record["policy_actions"])
    starts = np.asarray([s["robot"] for s in record["start_states"]])
    rolled = starts[:, None] + dt * np.cumsum(policy, axis=1)
    got = np.asarray([s["paths"]["policy"] for s in replay["starts"]])
    assert got == pytest.approx(rolled, abs=1e-3)


def test_replay_refuses_a_clip_the_bank_does_not_hold(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    shown = p.state()["step"]
    assert p.post("predictions", prediction_body(shown)).status_code == 201
    with client.app.state.engine.begin() as conn:
        conn.execute(update(TrialResponse.__table__).values(clip_sha256="f" * 64))
    public_id = dashboard(client, small_study.study_id)["participants"][0]["public_id"]
    base = f"/api/researcher/participants/{public_id}/trials"
    trial_id = client.get(base, params={"study_id": small_study.study_id},
                          headers=ADMIN).json()["trials"][0]["trial_id"]
    r = client.get(f"{base}/{trial_id}", params={"study_id": small_study.study_id},
                   headers=ADMIN)
    assert r.status_code == 409 and r.json()["detail"].startswith("clip_sha256:")
    r = client.get(f"{base}/nope", params={"study_id": small_study.study_id}, headers=ADMIN)
    assert r.status_code == 404


def test_the_headline_counts_usable_participants_not_finished_sessions(client, small_study,
                                                                       finished, tmp_path):
    """The dashboard's headline is the analysis' kept count under the study's own rules, with
    the finished sessions it excludes and why (not 'Completed 25 of 22')."""
    progress = dashboard(client, small_study.study_id, rules="live")["progress"]
    csv = client.get("/api/researcher/export.csv", params={"study_id": small_study.study_id},
                     headers=ADMIN).text
    (tmp_path / "export.csv").write_text(csv)
    config = load_study_config(small_study.settings("sqlite://"), small_study.study_id)
    counts = apply_exclusions(load_csv(tmp_path / "export.csv"), config.exclusions).counts()
    assert progress["usable"] == counts["participants_kept"] > 0
    assert progress["usable"] <= progress["completed"]
    assert set(progress["excluded_by_rule"]) <= {"failed_attention_check", "too_fast"}
    assert all(counts[f"excluded_{rule}"] == n for rule, n in progress["excluded_by_rule"].items())
