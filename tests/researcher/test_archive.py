"""`tomstudy archive` of a pilot, `reproduce` of it, `serve --archive`, and withdrawal naming
the archives that hold a participant."""

import asyncio
import json
import os
import shutil
import subprocess
import sys
import time
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import frictionless
import httpx
import pandas as pd
import pytest
from sqlalchemy import create_engine, select
from typer.testing import CliRunner

from app.cli import cli
from app.main import create_app
from app.pilot.bots import run_bots
from app.researcher.archive import ARCHIVE_MANIFEST, pseudonymous
from app.server.storage.tables import Participant
from app.settings import get_settings
from tests.conftest import (
    REPO,
    SmallStudy,
    free_port,
    local_client,
    patience,
    start_server,
    stop_server,
)

BOTS = 8
FREE_TEXT = "I watched where the robot was heading."  # every bot's answer to a text question
EXPORTS = ("predictions", "survey", "events", "participants")


@dataclass(frozen=True)
class Pilot:
    """A pilot of the small study: its database and a lab data dir of its own (the small
    study's bundles linked in), so the archive registry is this module's alone."""

    study: SmallStudy
    root: Path
    lab: Path
    db_url: str

    def env(self) -> dict[str, str]:
        """The lab's environment: its data dir, the study's configs and the pilot database."""
        return self.study.env(self.db_url, TOMSTUDY_DATA_DIR=str(self.lab))


@pytest.fixture(scope="module")
def pilot(small_study, tmp_path_factory) -> Pilot:
    """Coarse bots take the small study through a real server (their clocks trusted, so
    they count) into a fresh SQLite database."""
    root = tmp_path_factory.mktemp("archive")
    lab = root / "lab"
    lab.mkdir()
    (lab / "bundles").symlink_to(small_study.data_dir / "bundles")
    db_url = f"sqlite:///{root / 'pilot.db'}"
    port = free_port()
    proc = start_server(small_study, db_url, port, log=root / "server.log",
                        TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    try:
        results = asyncio.run(run_bots(f"http://127.0.0.1:{port}", small_study.study_id,
                                       "coarse", BOTS, concurrency=4))
    finally:
        stop_server(proc, grace_s=20)
    assert [r.error for r in results] == [None] * BOTS
    return Pilot(small_study, root, lab, db_url)


@contextmanager
def environment(values: dict[str, str]):
    """os.environ with `values` for the block (the CLI reads its settings from it)."""
    before = dict(os.environ)
    os.environ.update(values)
    get_settings.cache_clear()
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(before)
        get_settings.cache_clear()


def invoke(pilot: Pilot, *args: str):
    """`tomstudy ARGS` in this process, in the pilot lab's environment."""
    with environment(pilot.env()):
        return CliRunner().invoke(cli, list(args))


@pytest.fixture(scope="module")
def archived(pilot) -> Path:
    """The pilot's archive, as `tomstudy archive` writes it."""
    out = pilot.root / "out" / "pilot.zip"
    result = invoke(pilot, "archive", "--study", pilot.study.study_id, "--out", str(out))
    assert result.exit_code == 0, result.output
    assert f"wrote {out}" in result.stdout
    return out


def members(archive: Path) -> dict[str, bytes]:
    """Every member of a zip by name."""
    with zipfile.ZipFile(archive) as zf:
        return {name: zf.read(name) for name in zf.namelist()}


def platform_ids(pilot: Pilot) -> list[str]:
    """Every PROLIFIC_PID and SESSION_ID the bots arrived with."""
    engine = create_engine(pilot.db_url)
    with engine.connect() as conn:
        rows = conn.execute(select(Participant.external_id,
                                   Participant.recruitment_params)).all()
    engine.dispose()
    return [r.external_id for r in rows] + [r.recruitment_params["SESSION_ID"] for r in rows]


def test_the_archive_holds_exactly_its_listed_members(pilot, archived):
    files = members(archived)
    manifest = json.loads(files[ARCHIVE_MANIFEST])
    assert set(files) == {ARCHIVE_MANIFEST, *manifest["members"]}
    bundle = json.loads(files["bundle/manifest.json"])
    sid = pilot.study.study_id
    expected = ({"bundle/manifest.json", f"study/{sid}.yaml", "environment.json"}
                | {f"bundle/{name}" for name in bundle["files"]}
                | {f"exports/{what}.csv" for what in EXPORTS}
                | {f"exports/{what}.datapackage.json" for what in EXPORTS}
                | {"prereg/preregistration.md", "prereg/preregistration.html"})
    analysis = {name for name in files if name.startswith("analysis/")}
    assert set(files) - {ARCHIVE_MANIFEST} == expected | analysis
    assert {"analysis/summary.json", "analysis/report.html",
            "analysis/per_participant.csv"} <= analysis
    assert all(name.endswith((".json", ".csv", ".html")) for name in analysis)
    assert manifest["study_id"] == sid and manifest["format"] == "tomstudy-archive-v1"
    environment_lock = json.loads(files["environment.json"])
    assert environment_lock["python"].startswith(f"{sys.version_info.major}.")
    assert {"torch", "pandas", "tomstudy"} <= set(environment_lock["distributions"])


def test_every_archived_export_is_valid_against_its_codebook(archived, tmp_path):
    with zipfile.ZipFile(archived) as zf:
        zf.extractall(tmp_path)
    for what in EXPORTS:
        package = json.loads((tmp_path / "exports" / f"{what}.datapackage.json").read_text())
        assert "external_id" not in {f["name"] for f in package["resources"][0]["schema"][
            "fields"]}
        report = frictionless.validate(tmp_path / "exports" / f"{what}.datapackage.json")
        assert report.valid, (what, report.flatten(["rowNumber", "fieldName", "message"]))


def test_the_archive_names_its_participants_and_the_registry_holds_it(pilot, archived):
    manifest = json.loads(members(archived)[ARCHIVE_MANIFEST])
    engine = create_engine(pilot.db_url)
    with engine.connect() as conn:
        public = sorted(conn.execute(select(Participant.public_id)).scalars())
    engine.dispose()
    assert manifest["participant_ids"] == public
    registry = json.loads((pilot.lab / "archives" / "registry.json").read_text())
    assert [(e["path"], e["participant_ids"]) for e in registry] == [
        (str(archived.resolve()), public)]


def test_no_platform_id_and_no_free_text_by_default(pilot, archived):
    files = members(archived)
    ids = platform_ids(pilot)
    assert len(ids) == 2 * BOTS
    for name, data in files.items():
        assert not [i for i in ids if i.encode() in data], name
        assert FREE_TEXT.encode() not in data, name
    header = files["exports/participants.csv"].decode().splitlines()[0].split(",")
    assert "external_id" not in header and "completion_code" not in header
    survey = files["exports/survey.csv"].decode()
    assert "likert" in survey and ",text," not in survey


def test_free_text_answers_stay_only_when_asked():
    survey = pd.DataFrame({"participant_id": ["a", "a", "a"], "kind": ["likert", "text", ""],
                           "answer": ["5", FREE_TEXT, "an answer of a removed question"]})
    assert list(pseudonymous(survey, "survey", False)["kind"]) == ["likert"]
    assert list(pseudonymous(survey, "survey", True)["answer"]) == list(survey["answer"])


def test_reproduce_prints_every_number_equal(pilot, archived):
    result = invoke(pilot, "reproduce", str(archived))
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    numbers = [line for line in lines if line.endswith(("  equal", "  DIFFERS"))]
    assert len(numbers) > 100 and all(line.endswith("  equal") for line in numbers)
    assert any(line.startswith("summary.json ours_vs_vae.highway.") for line in numbers)
    assert any(line.startswith("per_participant.csv row 1 ") for line in numbers)
    assert lines[-1].startswith(f"{len(numbers)} numbers in ")
    assert lines[-1].endswith("every one equal to its recomputation")


def rewritten(archive: Path, out: Path, name: str, change) -> Path:
    """A copy of `archive` whose member `name` is `change(bytes)`, ARCHIVE.json untouched."""
    with zipfile.ZipFile(archive) as source, zipfile.ZipFile(out, "w",
                                                             zipfile.ZIP_DEFLATED) as zf:
        for info in source.infolist():
            data = source.read(info)
            zf.writestr(info, change(data) if info.filename == name else data)
    return out


def flip_first_digit(data: bytes) -> bytes:
    """The bytes with their first digit changed (one byte flipped)."""
    at = next(i for i, b in enumerate(data) if chr(b).isdigit())
    return data[:at] + (b"1" if data[at:at + 1] != b"1" else b"2") + data[at + 1:]


def test_a_tampered_member_is_refused_by_name(pilot, archived, tmp_path):
    tampered = rewritten(archived, tmp_path / "tampered.zip", "exports/predictions.csv",
                         flip_first_digit)
    result = invoke(pilot, "reproduce", str(tampered))
    assert result.exit_code == 1
    assert "exports/predictions.csv: altered (its SHA-256 is not ARCHIVE.json's)" in \
        result.output
    assert "summary.json" not in result.output  # nothing else named, nothing recomputed


def test_one_flipped_byte_of_the_zip_is_refused_by_name(pilot, archived, tmp_path):
    name = "analysis/summary.json"
    data = bytearray(archived.read_bytes())
    with zipfile.ZipFile(archived) as zf:
        info = zf.getinfo(name)
    header = info.header_offset
    start = header + 30 + int.from_bytes(data[header + 26:header + 28], "little") \
        + int.from_bytes(data[header + 28:header + 30], "little")  # past the local header
    data[start + info.compress_size // 2] ^= 0x01
    damaged = tmp_path / "damaged.zip"
    damaged.write_bytes(bytes(data))
    result = invoke(pilot, "reproduce", str(damaged))
    assert result.exit_code == 1
    assert f"{name}: altered" in result.output


def test_serve_archive_serves_the_study_from_the_archive_only(pilot, archived, tmp_path):
    review = tmp_path / "review"
    lab_db = Path(pilot.db_url.removeprefix("sqlite:///"))
    before = lab_db.read_bytes()
    port = free_port()
    log = tmp_path / "serve.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--archive", str(archived),
             "--archive-dir", str(review), "--port", str(port)],
            env=pilot.env(), cwd=REPO, stdout=out, stderr=subprocess.STDOUT)
        try:
            page = wait_for_page(proc, f"http://127.0.0.1:{port}/s/{pilot.study.study_id}", log)
        finally:
            stop_server(proc, grace_s=20)
    assert page.status_code == 200 and "<html" in page.text.lower()
    assert (review / "data" / "study.db").is_file()
    assert (review / "data" / "bundles" / pilot.study.study_id / "manifest.json").is_file()
    assert lab_db.read_bytes() == before
    assert not (pilot.lab / "study.db").exists()


def wait_for_page(proc: subprocess.Popen, url: str, log: Path) -> httpx.Response:
    """The page at `url` once the server answers 200 (60 s on a quiet machine)."""
    deadline = time.monotonic() + patience(60)
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"serve exited {proc.returncode}: {log.read_text()}")
        try:
            page = httpx.get(url, timeout=patience(1))
            if page.status_code == 200:
                return page
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise AssertionError(f"serve did not answer: {log.read_text()}")


def test_serve_archive_refuses_a_folder_in_use(pilot, archived, tmp_path):
    (tmp_path / "mine.txt").write_text("a lab's file")
    result = invoke(pilot, "serve", "--archive", str(archived), "--archive-dir", str(tmp_path),
                    "--port", "1")
    assert result.exit_code == 2 and "is not an empty folder" in result.output
    assert (tmp_path / "mine.txt").read_text() == "a lab's file"


def test_the_archived_study_serves_through_the_app_factory(pilot, archived, tmp_path):
    from app.researcher.reproduce import unpack_for_serving

    settings = pilot.study.settings("", data_dir=tmp_path / "data",
                                    configs_dir=tmp_path / "configs")
    study_id = unpack_for_serving(archived, settings)
    with local_client(create_app(settings, [study_id])) as client:
        assert client.get(f"/s/{study_id}").status_code == 200


def test_withdrawing_an_archived_participant_names_the_archive(pilot, archived):
    held = json.loads(members(archived)[ARCHIVE_MANIFEST])["participant_ids"]
    result = invoke(pilot, "withdraw", "--study", pilot.study.study_id,
                    "--participant-id", held[0])
    assert result.exit_code == 0, result.output
    line = json.loads(result.stdout)
    assert [a["path"] for a in line["archives"]] == [str(archived.resolve())]
    assert line["archives"][0]["sha256"] == json.loads(
        (pilot.lab / "archives" / "registry.json").read_text())[0]["sha256"]
    assert f"{archived.resolve()} (written " in result.stderr


def test_the_researcher_api_names_the_archive_too(pilot, archived):
    held = json.loads(members(archived)[ARCHIVE_MANIFEST])["participant_ids"]
    settings = pilot.study.settings(pilot.db_url, data_dir=pilot.lab)
    with local_client(create_app(settings, [pilot.study.study_id])) as client:
        answer = client.post("/api/researcher/withdrawals",
                             headers={"Authorization": "Bearer test-token"},
                             json={"study_id": pilot.study.study_id, "participant_id": held[-1]})
    assert answer.status_code == 201, answer.text
    assert [a["path"] for a in answer.json()["archives"]] == [str(archived.resolve())]


def test_an_unreadable_registry_stops_the_withdrawal_before_it_deletes(pilot, archived,
                                                                       tmp_path):
    broken = tmp_path / "lab"
    shutil.copytree(pilot.lab, broken, symlinks=True)
    (broken / "archives" / "registry.json").write_text("{not json")
    held = json.loads(members(archived)[ARCHIVE_MANIFEST])["participant_ids"]
    with environment(pilot.env() | {"TOMSTUDY_DATA_DIR": str(broken)}):
        result = CliRunner().invoke(cli, ["withdraw", "--study", pilot.study.study_id,
                                          "--participant-id", held[1]])
    assert result.exit_code == 1 and "registry.json: unreadable archive registry" in \
        result.output
    engine = create_engine(pilot.db_url)
    with engine.connect() as conn:
        assert held[1] in set(conn.execute(select(Participant.public_id)).scalars())
    engine.dispose()
