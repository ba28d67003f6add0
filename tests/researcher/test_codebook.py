"""Every export of a pilot comes with a codebook (a Frictionless Data Package) that the
`frictionless` library validates the CSV against: types, enums and patterns actually checked,
the file's sha256 and rows; over HTTP behind the token and from `tomstudy export --out`."""

import asyncio
import csv
import gzip
import hashlib
import io
import json
from pathlib import Path
from typing import get_args

import frictionless
import httpx
import pytest

from analysis.codebook import (
    ARMS,
    CLICK_INPUTS,
    EVENT_KINDS,
    OUTCOMES,
    QUESTION_KINDS,
    RECRUITMENTS,
    START_KINDS,
)
from analysis.exports import read_export
from app.cli import cli
from app.core.contracts import EXPORT_VERSION, PILOT, WHAT
from app.pilot.bots import run_bots
from app.server.flow.completion_codes import OUTCOMES as SERVED_OUTCOMES
from app.server.flow.recruitment import preview_key
from app.server.schemas import EVENT_DATA, SERVER_EVENTS, ClickInput, HistoryEntry
from app.study.config import MainTrialSelection, Platform, SurveyQuestion
from app.study.trials import TrialBank
from tests.conftest import REPO
from tests.researcher.downloads import export
from tests.server.flow import ADMIN, TOKEN, Participant

PILOT_BOTS = 3


def package(client, study_id: str, what: str) -> dict:
    """GET one export's data package."""
    r = client.get(f"/api/researcher/export/{what}.datapackage.json?study_id={study_id}",
                   headers=ADMIN)
    assert r.status_code == 200, r.text
    assert r.headers["content-disposition"].endswith(f'{study_id}_{what}.datapackage.json"')
    return r.json()


def saved(folder: Path, descriptor: dict, text: str) -> Path:
    """The package and its CSV written side by side, as a researcher saves the downloads;
    the package's path."""
    (folder / descriptor["resources"][0]["path"]).write_text(text)
    path = folder / "datapackage.json"
    path.write_text(json.dumps(descriptor))
    return path


def errors_of(report: frictionless.Report) -> list[tuple[str, str]]:
    """(error type, field name or note) of every error the report holds."""
    return [(e.type, getattr(e, "field_name", "") or e.note)
            for task in report.tasks for e in task.errors] + [
        (e.type, e.note) for e in report.errors]


@pytest.fixture
def pilot(client, small_study, study, bank):
    """The export tests' sessions, then the pilot bots (app/pilot/bots.py, as `make pilot`
    runs them) through the HTTP API, and one researcher's preview session."""
    transport = httpx.ASGITransport(app=client.app)
    results = asyncio.run(run_bots("http://localhost", small_study.study_id, "coarse",
                                   PILOT_BOTS, concurrency=1, transport=transport))
    assert [r.error for r in results] == [None] * PILOT_BOTS
    lab = Participant(client, small_study.study_id)
    lab.start(preview=preview_key(TOKEN, small_study.study_id))
    lab.pass_intro()
    lab.finish(bank)
    return study


def test_every_export_of_a_pilot_validates_against_its_codebook(client, small_study, pilot,
                                                                 tmp_path):
    sid = small_study.study_id
    for what in WHAT:
        descriptor = package(client, sid, what)
        text = export(client, sid, what)
        resource = descriptor["resources"][0]
        assert resource["path"] == f"{sid}_{what}.csv"
        assert resource["hash"] == "sha256:" + hashlib.sha256(text.encode()).hexdigest()
        assert resource["rows"] == len(text.splitlines()) - 1 > 0
        assert descriptor["export_version"] == EXPORT_VERSION
        folder = tmp_path / what
        folder.mkdir()
        report = frictionless.validate(saved(folder, descriptor, text))
        assert report.valid, (what, errors_of(report))
        assert report.tasks[0].stats["rows"] == resource["rows"]


def test_the_codebook_names_the_study_hashes_the_rows_carry(client, small_study, pilot):
    ctx = client.app.state.studies[small_study.study_id]
    for what in WHAT:
        hashes = package(client, small_study.study_id, what)["study_hashes"]
        rows = read_export(io.StringIO(export(client, small_study.study_id, what)), what)
        assert hashes["config_sha256"] == sorted(set(rows["config_sha256"])), what
        assert hashes["bank_sha256"] == [ctx.bank.sha256], what
        models = [json.loads(m) for m in hashes["models_sha256"] if m != "{}"]
        assert models and all(set(m) <= set(ctx.config.worlds) for m in models), what
    sheet = package(client, small_study.study_id, "participants")["study_hashes"]
    assert sheet["config_sha256"] == sorted({ctx.config_sha256, "0" * 64})  # done2's changed
    predicted = package(client, small_study.study_id, "predictions")["study_hashes"]
    assert set(predicted["models_sha256"]) <= set(sheet["models_sha256"])
    fields = {f["name"]: f for f in package(client, small_study.study_id,
                                            "predictions")["resources"][0]["schema"]["fields"]}
    assert fields["world"]["constraints"]["enum"] == list(ctx.config.worlds)
    assert fields["recruitment"]["constraints"]["enum"] == list(RECRUITMENTS)
    assert fields["participant_click_x"]["unit"] == "m"
    survey = package(client, small_study.study_id, "survey")["resources"][0]["schema"]
    answer = next(f for f in survey["fields"] if f["name"] == "answer")
    assert "PERSONAL DATA" in answer["description"]


@pytest.mark.parametrize(("what", "column", "bad"), [
    ("predictions", "arm", "sideways"), ("predictions", "clip_sha256", "not-a-hash"),
    ("predictions", "recruitment", "email"), ("participants", "attention_verdict", "maybe"),
    ("participants", "pilot", "yes"), ("events", "kind", "keypress"),
    ("survey", "question", "favourite_colour"),
    ("participants", "exclusion_reasons", "too_fast;bogus")])
def test_a_value_outside_its_constraint_fails_validation_naming_its_field(
        client, small_study, study, tmp_path, what, column, bad):
    descriptor = package(client, small_study.study_id, what)
    rows = list(csv.reader(io.StringIO(export(client, small_study.study_id, what))))
    rows[1][rows[0].index(column)] = bad
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows)
    corrupt = buffer.getvalue()
    descriptor["resources"][0] |= {
        "hash": "sha256:" + hashlib.sha256(corrupt.encode()).hexdigest(),
        "bytes": len(corrupt.encode())}
    report = frictionless.validate(saved(tmp_path, descriptor, corrupt))
    assert not report.valid
    assert {name for _, name in errors_of(report)} == {column}


def test_a_changed_csv_fails_on_its_sha256(client, small_study, study, tmp_path):
    descriptor = package(client, small_study.study_id, "survey")
    text = export(client, small_study.study_id, "survey").replace("followed", "Followed")
    report = frictionless.validate(saved(tmp_path, descriptor, text))
    assert not report.valid and "hash-count" in {kind for kind, _ in errors_of(report)}


def test_tomstudy_export_writes_the_codebook_beside_the_csv(client, small_study, pilot,
                                                            cli_env, tmp_path):
    for what in WHAT:
        out = tmp_path / f"{what}.csv"
        result = cli_env.invoke(cli, ["export", "--study", small_study.study_id, "--what",
                                      what, "--out", str(out)])
        assert result.exit_code == 0, result.output
        written = tmp_path / f"{what}.datapackage.json"
        assert f"its codebook {written}" in result.stderr
        descriptor = json.loads(written.read_text())
        assert descriptor["resources"][0]["path"] == out.name
        report = frictionless.validate(written)
        assert report.valid, (what, errors_of(report))
    to_stdout = cli_env.invoke(cli, ["export", "--study", small_study.study_id])
    assert to_stdout.exit_code == 0
    assert "give --out FILE.csv to write FILE.datapackage.json" in to_stdout.stderr
    assert "datapackage" not in to_stdout.stdout


def test_the_codebook_routes_need_the_token(client, small_study):
    query = f"?study_id={small_study.study_id}"
    paths = [f"/api/researcher/export/{what}.datapackage.json{query}" for what in WHAT]
    for path in [*paths, f"/api/researcher/export.datapackage.json{query}"]:
        assert client.get(path).status_code == 401, path
        assert client.get(path, headers={"Authorization": "Bearer nope"}).status_code == 403
    r = client.get(f"/api/researcher/export/clicks.datapackage.json{query}", headers=ADMIN)
    assert r.status_code == 422 and "what" in r.text
    r = client.get(f"/api/researcher/export.datapackage.json{query}", headers=ADMIN)
    assert r.status_code == 200 and r.json()["resources"][0]["name"] == "predictions"


def test_the_closed_sets_are_the_ones_the_code_writes(small_study, interaction_study):
    assert OUTCOMES == SERVED_OUTCOMES
    assert (*get_args(Platform), PILOT) == RECRUITMENTS
    assert get_args(MainTrialSelection.model_fields["rule"].annotation) == ARMS
    assert get_args(ClickInput) == CLICK_INPUTS
    assert get_args(SurveyQuestion.model_fields["kind"].annotation) == QUESTION_KINDS
    presses = get_args(HistoryEntry.model_fields["action"].annotation)
    assert set(EVENT_KINDS) == {*EVENT_DATA, *SERVER_EVENTS, *presses}
    kinds = set()
    for built in (small_study, interaction_study):
        bank = TrialBank.load(built.layout, built.study_id)
        kinds |= {s.start_kind for w in bank.data.worlds.values() for t in w.trials
                  for s in t.start_states}
    paper = json.loads(gzip.decompress(
        (REPO / "study_configs/bundles/paper_study/bank.json.gz").read_bytes()))
    kinds |= {s["start_kind"] for w in paper["worlds"].values() for t in w["trials"]
              for s in t["start_states"]}
    assert kinds <= set(START_KINDS) and {"own", "same_lane", "near", "far"} <= kinds
