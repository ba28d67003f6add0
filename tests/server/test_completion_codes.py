"""Completion codes nobody can guess: generated per study on first use, kept in the data dir
(the same for every worker and after a restart), shown to the researcher, used in the
redirects; production refuses a code the repository makes public (issue 32 item 3)."""

import json
import multiprocessing
import re
import shutil
import stat
import subprocess

import pytest
import yaml

from app.configio import ConfigError, load_yaml_model
from app.layout import Layout
from app.main import UnsafeSettings, create_app
from app.server.flow.completion_codes import (
    OUTCOMES,
    PublicCode,
    public_codes,
    refuse_public_codes,
    study_codes,
)
from app.settings import REPO_ROOT
from app.study.config import StudyConfig
from tests.conftest import REPO, TOMSTUDY, local_client, patience
from tests.server.flow import ADMIN, Participant, new_id, served_codes

CODE = re.compile(r"^[A-HJKMNP-TV-Z2-9]{10}$")
STRONG = {"production": True, "admin_token": "x" * 40,
          "rate_limit_starts": "20/minute", "rate_limit_requests": "300/minute"}


def _codes_in_worker(root: str, barrier) -> dict:
    barrier.wait()  # every worker asks at the same moment
    return study_codes(Layout(root), "race_study")


RACERS = 3  # more than this machine's 2 cores, so they race; each spawn costs an import


def test_workers_starting_at_once_agree_on_one_set_of_random_codes(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(RACERS)
        with ctx.Pool(RACERS) as pool:
            answers = pool.starmap(_codes_in_worker, [(str(tmp_path), barrier)] * RACERS)
    assert all(a == answers[0] for a in answers)
    codes = answers[0]
    assert list(codes) == list(OUTCOMES) and len(set(codes.values())) == len(OUTCOMES)
    assert all(CODE.match(code) for code in codes.values())
    path = Layout(tmp_path).completion_codes("race_study")
    assert json.loads(path.read_text())["codes"] == codes
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary file left
    assert study_codes(Layout(tmp_path), "other_study") != codes


def test_a_served_session_ends_with_its_generated_code_the_same_after_a_restart(
        small_study, tmp_path):
    sid = small_study.study_id
    settings = small_study.settings(f"sqlite:///{tmp_path / 'study.db'}")
    kept = study_codes(small_study.layout, sid)
    assert served_codes(small_study) == kept
    for _ in range(2):  # a restart reads the same file
        with local_client(create_app(settings, [sid])) as client:
            p = Participant(client, sid)
            p.start()
            ended = p.post("decline", {"submission_id": new_id()}).json()["step"]
            assert ended["completion_code"] == kept["declined_consent"]
            assert ended["redirect_url"].endswith(f"cc={kept['declined_consent']}")
            board = client.get(f"/api/researcher/dashboard?study_id={sid}", headers=ADMIN)
            assert [(row["ending"], row["completion_code"]) for row in
                    board.json()["completion_codes"]] == list(kept.items())
            assert "approve" in board.json()["completion_codes"][0]["prolific_action"]
    public = {code for code, _ in public_codes(REPO_ROOT / "study_configs")}
    assert not public & set(kept.values())


def test_the_shipped_studies_pin_no_code():
    for name in ("paper_study", "interaction_study"):
        config = load_yaml_model(REPO / "study_configs" / f"{name}.yaml", StudyConfig)
        assert config.recruitment.codes == "generated"
        assert config.recruitment.pinned_codes() == {}


def test_production_refuses_a_code_the_repository_makes_public(small_study, tmp_path):
    configs = tmp_path / "configs"
    shutil.copytree(small_study.configs_dir, configs)
    path = configs / f"{small_study.study_id}.yaml"
    study = yaml.safe_load(path.read_text())
    study["recruitment"].pop("codes")
    study["recruitment"]["completion_code"] = "MYOWNCODE1"
    study["recruitment"]["endings"]["failed_checks"]["completion_code"] = "C2TOMREVIEW"
    path.write_text(yaml.safe_dump(study))
    config = load_yaml_model(path, StudyConfig)
    with pytest.raises(PublicCode, match=r"recruitment\.endings\.failed_checks\."
                                         r"completion_code: 'C2TOMREVIEW' is public"):
        refuse_public_codes(config, small_study.study_id)
    settings = small_study.settings(f"sqlite:///{tmp_path / 'p.db'}", configs_dir=configs,
                                    **STRONG)
    with pytest.raises(UnsafeSettings, match="failed_checks.completion_code"):
        create_app(settings, [small_study.study_id])
    env = small_study.env(f"sqlite:///{tmp_path / 's.db'}", TOMSTUDY_CONFIGS_DIR=str(configs),
                          TOMSTUDY_PRODUCTION="1", TOMSTUDY_ADMIN_TOKEN="x" * 40,
                          TOMSTUDY_RATE_LIMIT_STARTS="20/minute",
                          TOMSTUDY_RATE_LIMIT_REQUESTS="300/minute")
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1", "--study", small_study.study_id],
                         env=env, cwd=REPO, capture_output=True, text=True, timeout=patience(60))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "recruitment.endings.failed_checks.completion_code: 'C2TOMREVIEW' is public" in (
        run.stderr)
    study["recruitment"]["endings"]["failed_checks"]["completion_code"] = "MYOWNCODE2"
    path.write_text(yaml.safe_dump(study))  # the lab's own codes serve
    refuse_public_codes(load_yaml_model(path, StudyConfig), small_study.study_id)


@pytest.mark.parametrize(("recruitment", "field"), [
    ({"codes": "generated", "completion_code": "ABC"}, "recruitment.completion_code"),
    ({"codes": "generated", "endings": {"screened_out": {"completion_code": "X"}}},
     "recruitment.endings.screened_out.completion_code"),
    ({"platform": "prolific"}, "completion_code: required"),
])
def test_codes_come_from_one_place(tmp_path, recruitment, field):
    study = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    study["recruitment"] = recruitment
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(study))
    with pytest.raises(ConfigError, match=re.escape(field)):
        load_yaml_model(path, StudyConfig)


def test_tomstudy_codes_prints_each_ending_with_its_prolific_action(small_study):
    run = subprocess.run([TOMSTUDY, "codes", "--study", small_study.study_id],
                         env=small_study.env("sqlite://"), cwd=REPO, capture_output=True,
                         text=True, timeout=patience(60))
    assert run.returncode == 0, run.stderr
    codes = study_codes(small_study.layout, small_study.study_id)
    lines = run.stdout.splitlines()
    assert "generated" in lines[0] and len(lines) == 1 + len(OUTCOMES)
    assert lines[1].split()[:2] == ["completed", codes["completed"]]
    assert "approve and pay" in lines[1] and "request a return" in lines[4]
