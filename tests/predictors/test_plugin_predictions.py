"""A participant's answer on a study with the CTRV plug-in: stored beside every predictor's in
one transaction, exported exactly (columns ctrv_vx, ctrv_vy, ctrv_code, ctrv_sha256), read back
alike from the CSV and the database, and listed on the dashboard."""

import io

import frictionless
import numpy as np
import pandas as pd
import pytest
from sqlalchemy import select
from sqlmodel import Session

from analysis.load import load_csv, load_database
from app.core.alignment import alignment_error
from app.core.contracts import (
    COARSE_OBSERVERS,
    EXPORT_COLUMNS,
    MODEL_COLORS,
    model_color,
    plugin_columns,
)
from app.predictors.ctrv import CTRV
from app.predictors.protocol import ask
from app.server.storage.db import make_engine
from app.server.storage.tables import PredictionRow
from app.study.trials import TrialBank
from tests.server.flow import ADMIN, at_first_trial, prolific

STORED = [*COARSE_OBSERVERS, "ctrv"]  # the code predictors a row stores, in export order


@pytest.fixture(scope="session")
def served_study(ctrv_study):
    """This module's `client` and `bank` serve the CTRV study."""
    return ctrv_study


@pytest.fixture(scope="module")
def dt_of(ctrv_study) -> dict[str, float]:
    """Each world's dt [s] in the CTRV study's bank."""
    bank = TrialBank.load(ctrv_study.layout, ctrv_study.study_id)
    return {world: entry.dt_s for world, entry in bank.data.worlds.items()}


def finished_export(client, study_id: str, bank: dict) -> str:
    """One participant through the whole study; the predictions export's CSV text."""
    p = at_first_trial(client, study_id, **prolific("plugin"))
    p.finish(bank)
    r = client.get("/api/researcher/export.csv", params={"study_id": study_id}, headers=ADMIN)
    assert r.status_code == 200, r.text
    return r.text


def ctrv_of(trial: dict, dt_s: float, steps: int = 3) -> np.ndarray:
    """CTRV's answer [K, n, 2] to a bank trial, computed here."""
    starts = np.array([[s["robot"], s["human"]] for s in trial["start_states"]])
    headings = [s["robot_heading"] for s in trial["start_states"]]
    return ask(CTRV(), trial["model_input"], starts, headings, dt_s, steps).actions


def test_a_plugins_answer_is_stored_and_exported_exactly(client, ctrv_study, bank, dt_of,
                                                         db_url):
    text = finished_export(client, ctrv_study.study_id, bank)
    frame = pd.read_csv(io.StringIO(text))
    assert list(frame.columns) == [*EXPORT_COLUMNS, *(column for name in STORED
                                                      for column in plugin_columns(name))]
    assert len(frame) > 0 and frame["trial_id"].nunique() > 5
    assert (frame["ctrv_code"] == -1).all()
    assert set(frame["ctrv_sha256"]) == {CTRV().content_hash}
    for (trial_id, start, step), row in frame.set_index(
            ["trial_id", "start_index", "step"]).iterrows():
        trial = bank[trial_id]
        stored = trial["predictions"]["ctrv"][0]["actions"][start][step]
        exported = [row["ctrv_vx"], row["ctrv_vy"]]
        assert np.round(exported, 5).tolist() == stored  # the bank's, as the bank rounds
        answer = ctrv_of(trial, dt_of[trial["world"]])
        assert exported == answer[start, step].tolist()  # the server's, exactly
        for name in COARSE_OBSERVERS:
            assert (np.round([row[f"{name}_vx"], row[f"{name}_vy"]], 5).tolist()
                    == trial["predictions"][name][0]["actions"][start][step])
    from_csv = load_csv(io.StringIO(text))
    from_db = load_database(db_url, ctrv_study.study_id)
    pd.testing.assert_frame_equal(from_db, from_csv)
    assert from_csv["ctrv_code"].dtype == np.int64 and from_csv["ctrv_vx"].dtype == np.float64


def test_the_rows_hold_the_plugin_in_their_plugins_column(client, ctrv_study, bank,
                                                          db_url):
    finished_export(client, ctrv_study.study_id, bank)
    engine = make_engine(db_url)
    with Session(engine) as db:
        cells = db.execute(select(PredictionRow.plugins, PredictionRow.ours_sha256)).all()
    engine.dispose()
    assert cells and all(set(plugins) == set(STORED) and set(plugins["ctrv"]) ==
                         {"vx", "vy", "code", "sha256"} for plugins, _ in cells)


def test_the_dashboard_and_summary_list_every_predictor(client, ctrv_study, bank):
    export = load_csv(io.StringIO(finished_export(client, ctrv_study.study_id, bank)))
    r = client.get("/api/researcher/dashboard", params={"study_id": ctrv_study.study_id},
                        headers=ADMIN)
    assert r.status_code == 200, r.text
    alignment = r.json()["alignment"]
    names = ["ours", "vae", "cv", *STORED, "policy"]
    assert alignment["predictors"] == names
    assert alignment["style"]["labels"]["ctrv"] == "ctrv"
    assert alignment["style"]["colors"]["ctrv"] == model_color("ctrv")
    assert alignment["style"]["colors"]["ours"] == MODEL_COLORS["ours"]
    scored = export[~export["is_practice"] & ~export["attention_check"]]
    assert set(alignment["worlds"]) == {"highway", "obstacle"}
    for world, entry in alignment["worlds"].items():
        assert list(entry["models"]) == names, world
        (mine,) = entry["models"]["ctrv"]["participants"]
        rows = scored[scored["world"] == world]
        by_hand = alignment_error(rows[["participant_vx", "participant_vy"]].to_numpy(),
                                  rows[["ctrv_vx", "ctrv_vy"]].to_numpy()).mean()
        assert mine == pytest.approx(by_hand, abs=1e-5)
    summary = client.get("/api/researcher/summary", params={"study_id": ctrv_study.study_id},
                              headers=ADMIN).json()
    kept = summary["alignment_error"]["kept"]
    assert kept and all(0 <= kept[w]["ctrv"] <= 2 for w in kept)


def test_the_replay_draws_the_plugin_from_its_stored_answer(client, ctrv_study, bank, dt_of):
    finished_export(client, ctrv_study.study_id, bank)
    board = client.get("/api/researcher/dashboard", params={"study_id": ctrv_study.study_id},
                            headers=ADMIN).json()
    public_id = board["participants"][0]["public_id"]
    base = f"/api/researcher/participants/{public_id}/trials"
    trials = client.get(base, params={"study_id": ctrv_study.study_id}, headers=ADMIN)
    trial_id = trials.json()["trials"][-1]["trial_id"]
    replay = client.get(f"{base}/{trial_id}", params={"study_id": ctrv_study.study_id},
                             headers=ADMIN).json()
    assert replay["models"] == ["ours", "vae", "policy", *STORED]
    record = bank[trial_id]
    starts = np.asarray([s["robot"] for s in record["start_states"]])
    dt_s = dt_of[record["world"]]
    rolled = starts[:, None] + dt_s * np.cumsum(ctrv_of(record, dt_s), axis=1)
    got = np.asarray([s["paths"]["ctrv"] for s in replay["starts"]])
    assert got == pytest.approx(rolled, abs=1e-3)


def test_the_codebook_describes_and_validates_the_plugins_columns(client, ctrv_study, bank,
                                                                  tmp_path):
    text = finished_export(client, ctrv_study.study_id, bank)
    r = client.get("/api/researcher/export.datapackage.json",
                   params={"study_id": ctrv_study.study_id}, headers=ADMIN)
    assert r.status_code == 200, r.text
    resource = r.json()["resources"][0]
    fields = {f["name"]: f for f in resource["schema"]["fields"]}
    assert "plug-in predictor ctrv" in fields["ctrv_vx"]["description"]
    assert fields["ctrv_code"]["type"] == "integer" and fields["ctrv_vy"]["unit"] == "m/s"
    (tmp_path / resource["path"]).write_text(text)
    (tmp_path / "datapackage.json").write_text(r.text)
    report = frictionless.validate(tmp_path / "datapackage.json")
    assert report.valid, report.flatten(["type", "fieldName", "note"])
