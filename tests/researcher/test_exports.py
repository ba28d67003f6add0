"""The four researcher exports: typed, pseudonymous, versioned, spreadsheet-safe, and the
predictions export read by `tomstudy analyze` as it is."""

import io
import json
import subprocess

import numpy as np
import pandas as pd
from sqlmodel import Session

from analysis.exports import read_export
from analysis.load import load_csv, load_database
from app.cli import cli
from app.core.contracts import (
    BOOL_COLUMNS,
    COARSE_OBSERVERS,
    EXPORT_COLUMNS,
    INT_COLUMNS,
    SCHEMAS,
    WHAT,
    plugin_columns,
)
from app.researcher.exports import export_table
from app.server.storage.tables import Participant
from tests.conftest import TOMSTUDY, patience
from tests.researcher.downloads import FORMULA, export
from tests.server.flow import ADMIN, prolific

PANDAS_DTYPES = {"text": "str", "int": np.int64, "float": np.float64, "bool": bool,
                 "time": "datetime64[us, UTC]"}


def public_ids(client) -> dict[str, str]:
    """external id -> public id, read from the database."""
    with client.app.state.engine.connect() as conn:
        rows = conn.execute(Participant.__table__.select()).mappings().all()
    return {r["external_id"]: r["public_id"] for r in rows}


def test_each_export_reads_back_with_its_dtypes(client, small_study, study):
    ctx = client.app.state.studies[small_study.study_id]
    for what in WHAT[1:]:
        text = export(client, small_study.study_id, what)
        frame = read_export(io.StringIO(text), what)
        with Session(client.app.state.engine) as db:
            built = export_table(db, ctx.config, small_study.study_id, what)
        pd.testing.assert_frame_equal(frame, built.reset_index(drop=True))
        # the served file's own header (read_export fills any missing column, so check it raw)
        header = list(pd.read_csv(io.StringIO(text), nrows=0).columns)
        assert header == list(SCHEMAS[what]), what
        for col, kind in SCHEMAS[what].items():
            assert frame[col].dtype == PANDAS_DTYPES[kind], (what, col, frame[col].dtype)
        plain = pd.read_csv(io.StringIO(text))  # a researcher's bare read: numbers stay numbers
        for col, kind in SCHEMAS[what].items():
            if kind in ("int", "float", "bool") and len(plain):
                assert plain[col].dtype == PANDAS_DTYPES[kind], (what, col, plain[col].dtype)
    predictions = read_export(io.StringIO(export(client, small_study.study_id, "predictions")),
                              "predictions")
    assert list(predictions.columns) == [*EXPORT_COLUMNS, *(c for name in COARSE_OBSERVERS
                                                            for c in plugin_columns(name))]
    assert all(predictions[c].dtype == bool for c in BOOL_COLUMNS)
    assert all(predictions[c].dtype == np.int64 for c in INT_COLUMNS)


def test_the_analysis_exports_are_pseudonymous_and_versioned(client, small_study, study):
    ids = public_ids(client)
    ctx = client.app.state.studies[small_study.study_id]
    for what in ("predictions", "survey", "events"):
        text = export(client, small_study.study_id, what)
        assert "external_id" not in text.splitlines()[0]
        assert not any(ext in text for ext in ids if ext), what
        frame = read_export(io.StringIO(text), what)
        assert set(frame["participant_id"]) <= set(ids.values())
        changed = {ctx.config_sha256, "0" * 64}  # done2 ran another config
        assert set(frame["config_sha256"]) == (changed if what != "events"
                                               else {ctx.config_sha256}), what
        assert set(frame["bank_sha256"]) == {ctx.bank.sha256}
    survey = read_export(io.StringIO(export(client, small_study.study_id, "survey")), "survey")
    models = json.loads(survey["models_sha256"].iloc[0])
    assert set(models) == {"highway", "obstacle"} and set(models["highway"]) == {"ours", "vae"}
    predictions = load_csv(io.StringIO(export(client, small_study.study_id, "predictions")))
    pinned = predictions.groupby("world")["ours_sha256"].first().to_dict()
    assert {w: m["ours"] for w, m in models.items()} == pinned


def test_survey_rows_keep_formula_answers_as_text(client, small_study, study):
    text = export(client, small_study.study_id, "survey")
    raw = pd.read_csv(io.StringIO(text))
    assert "'" + FORMULA in set(raw["answer"])  # a spreadsheet shows it, never runs it
    survey = read_export(io.StringIO(text), "survey")
    assert len(survey) == 3 * 4 and FORMULA in set(survey["answer"])
    kinds = dict(zip(survey["question"], survey["kind"], strict=False))
    assert kinds == {"difficulty": "likert", "confidence": "likert", "driving": "choice",
                     "strategy": "text"}
    assert set(survey.loc[survey["question"] == "difficulty", "answer"]) == {"4"}
    assert survey["answered_at"].notna().all()


def test_events_hold_telemetry_and_undo_history(client, small_study, study, bank):
    frame = read_export(io.StringIO(export(client, small_study.study_id, "events")), "events")
    telemetry = frame[frame["source"] == "telemetry"]
    assert list(telemetry["kind"]) == ["clip_finished", "resize"]
    assert telemetry["trial_id"].iloc[0] in bank  # the opaque id mapped back to the bank's
    assert (telemetry["w"].iloc[1], telemetry["h"].iloc[1]) == (800, 600)
    assert (telemetry["start_index"] == -1).all() and telemetry["t_trial_ms"].isna().all()
    history = frame[frame["source"] == "trial_history"]
    assert list(history["kind"]) == ["undo", "reset"]
    assert list(history["start_index"]) == [2, 0]
    assert list(history["t_trial_ms"]) == [1500.0, 2500.0]
    assert set(history["trial_id"]) == {study["history_trial"]}
    assert (history["t_client_ms"] - history["t_trial_ms"]).nunique() == 1  # shown_at_ms


def test_participants_sheet(client, small_study, study):
    sheet = read_export(io.StringIO(export(client, small_study.study_id, "participants")),
                        "participants")
    by_ext = sheet.set_index("external_id")
    done0 = by_ext.loc[prolific("done0")["PROLIFIC_PID"]]
    assert (done0["outcome"], done0["completion_code"], done0["status"]) == (
        "completed", "C1TOMSTUDY", "ended")
    assert done0["attention_verdict"] == "passed" and done0["attention_checks"] == 2
    assert done0["duration_min"] >= 0 and done0["steps_done"] == done0["steps_total"] - 1
    running = by_ext.loc[prolific("running")["PROLIFIC_PID"]]
    assert (running["status"], running["outcome"], running["attention_verdict"]) == (
        "in_progress", "", "none")
    assert pd.isna(running["ended_at"]) and np.isnan(running["duration_min"])
    assert running["models_sha256"] == "{}"  # no answer yet; bank_sha256 pins both models
    assert not sheet["pilot"].any() and not sheet["replaced"].any()
    assert set(sheet["participant_id"]) == set(public_ids(client).values())


def test_tomstudy_analyze_reads_the_predictions_export_unchanged(client, small_study, study,
                                                                 db_url, tmp_path):
    path = tmp_path / "predictions.csv"
    path.write_text(export(client, small_study.study_id, "predictions"))
    pd.testing.assert_frame_equal(load_csv(path), load_database(db_url, small_study.study_id))
    out = tmp_path / "report"
    done = subprocess.run(
        [TOMSTUDY, "analyze", "--study",
         small_study.study_id, "--csv", str(path), "--out", str(out)],
        env=small_study.env(db_url), capture_output=True, text=True, timeout=patience(300))
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert {res["n"] for res in summary["ours_vs_vae"].values()} == {3}


def test_tomstudy_export_writes_what_the_endpoint_serves(client, small_study, study, cli_env,
                                                         tmp_path):
    for what in WHAT:
        result = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--what", what])
        assert result.exit_code == 0, result.output
        served = export(client, small_study.study_id, what)
        if what == "participants":  # status (stale/in progress) depends on the time of asking
            served, result_text = (read_export(io.StringIO(t), what).drop(columns="status")
                                   for t in (served, result.stdout))
            pd.testing.assert_frame_equal(served, result_text)
        else:
            assert result.stdout == served
    out = tmp_path / "survey.csv"
    result = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--what", "survey",
                                  "--out", str(out)])
    assert result.exit_code == 0 and len(read_export(out, "survey")) == 12


def test_tomstudy_export_names_a_bad_option(client, small_study, cli_env):
    bad = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--what", "clicks"])
    assert bad.exit_code == 2 and "--what: unknown export 'clicks'" in bad.output
    unknown = cli_env.invoke(cli, ["export", "--study", "no_such_study"])
    assert unknown.exit_code == 2 and "--study: unknown study 'no_such_study'" in unknown.output


def test_every_researcher_endpoint_needs_the_token(client, small_study):
    query = f"?study_id={small_study.study_id}"
    gets = [f"/api/researcher/export/{what}.csv{query}" for what in WHAT]
    gets += [f"/api/researcher/export.csv{query}", f"/api/researcher/withdrawals/audit{query}"]
    for path in gets:
        assert client.get(path).status_code == 401, path
        assert client.get(path, headers={"Authorization": "Bearer nope"}).status_code == 403
    body = {"study_id": small_study.study_id, "external_id": "x"}
    assert client.post("/api/researcher/withdrawals", json=body).status_code == 401
    r = client.get(f"/api/researcher/export/clicks.csv{query}", headers=ADMIN)
    assert r.status_code == 422 and "what" in r.text
    r = client.get("/api/researcher/export/survey.csv?study_id=nope", headers=ADMIN)
    assert r.status_code == 404 and r.json()["detail"].startswith("study_id:")


def test_tomstudy_export_makes_a_missing_folder_and_names_a_bad_target(client, small_study,
                                                                       cli_env, tmp_path):
    out = tmp_path / "not" / "yet" / "survey.csv"
    made = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--what", "survey",
                                "--out", str(out)])
    assert made.exit_code == 0, made.output
    assert len(read_export(out, "survey")) == len(export_rows(client, small_study, "survey"))
    folder = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--out",
                                  str(tmp_path)])
    assert folder.exit_code == 2
    assert folder.output.strip().splitlines() == [
        f"error: --out: {tmp_path} is a folder; give a CSV file name"]
    under_a_file = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--out",
                                        str(out / "x.csv")])
    assert under_a_file.exit_code == 2 and len(under_a_file.output.strip().splitlines()) == 1
    assert under_a_file.output.startswith(f"error: --out: cannot make the folder {out}")


def export_rows(client, small_study, what: str) -> pd.DataFrame:
    """The served export `what`, read back."""
    return read_export(io.StringIO(export(client, small_study.study_id, what)), what)
