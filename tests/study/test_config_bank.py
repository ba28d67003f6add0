"""The study config, the trial bank, the predictor's check, prepare, production refusal."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient
from sqlalchemy.pool import StaticPool
from sqlmodel import Session, create_engine, select

from app.configio import ConfigError, load_yaml_model
from app.fileio import sha256_file
from app.settings import DEFAULT_ADMIN_TOKEN, Settings
from app.study.config import StudyConfig, load_study_config
from app.study.db import create_tables
from app.study.deps import get_db
from app.study.main import UnsafeSettings, create_app
from app.study.predictor import BankMismatch, Predictor
from app.study.prepare import bank_is_current, prepare_study
from app.study.tables import Participant
from app.study.trial_builder import build_trials
from app.study.trials import BANK_FILE, TrialBank, bank_dir, clip_sha256
from tests.study.flow import new_id

REPO = Path(__file__).resolve().parents[2]


def test_paper_study_config_matches_the_paper():
    cfg = load_study_config(Settings(), "paper_study")
    assert cfg.worlds == ["highway", "obstacle"] and cfg.counterbalance_world_order
    assert (cfg.trials_per_world, cfg.examples_per_trial, cfg.start_states,
            cfg.steps_to_predict, cfg.target_sample_size) == (10, 4, 5, 3, 22)
    assert (cfg.segment_steps.min, cfg.segment_steps.max) == (5, 7)
    assert cfg.recruitment.prolific_params == ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID"]
    assert cfg.recruitment.mturk_params == ["workerId", "assignmentId", "hitId"]


@pytest.mark.parametrize("change, field", [
    ({"titel": "x"}, "titel"),
    ({"trials_per_world": -1}, "trials_per_world"),
    ({"segment_steps": {"min": 7, "max": 5}}, "segment_steps"),
    ({"worlds": ["highway", "mars"]}, "worlds.1"),
    ({"recruitment": {"completion_code": "X", "prolific_url": "u"}}, "recruitment.prolific_url"),
])
def test_config_errors_name_the_key(tmp_path, change, field):
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    data.update(change)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=f"bad.yaml: {field}"):
        load_yaml_model(path, StudyConfig)


@pytest.fixture(scope="module")
def bank(small_study) -> TrialBank:
    return TrialBank.load(small_study.data_dir, small_study.study_id)


def test_bank_trials_have_the_paper_shape(bank, small_study):
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    for name, world in bank.data.worlds.items():
        kinds = [t.kind for t in world.trials]
        assert kinds.count("main") == cfg.bank_trials_per_world > cfg.trials_per_world
        assert kinds.count("practice") == 1 and kinds.count("attention") == 1
        assert 0 < world.min_step_m < world.max_step_m
        b = world.scene["bounds"]
        for t in world.trials:
            seg = np.asarray(t.segment.positions)
            assert 5 <= len(seg) - 1 <= 7 and seg.shape[1:] == (2, 2)
            assert len(t.examples) == 4
            assert t.source_index not in [e.source_index for e in t.examples]
            assert len({e.robot_label for e in t.examples}) >= min(
                2, len(world.label_names))
            starts = np.array([[s.robot, s.human] for s in t.start_states])
            assert starts.shape == (5, 2, 2)
            np.testing.assert_allclose(starts[0], seg[-1])  # robot's own segment end first
            np.testing.assert_allclose(starts[:, 1], np.repeat(seg[-1:, 1], 5, 0))  # human fixed
            assert len({tuple(p) for p in starts[:, 0]}) == 5
            assert (starts[..., 0] >= b["x_min_m"]).all() and (starts[..., 0] <= b["x_max_m"]).all()
            for kind in ("ours", "vae"):
                assert np.asarray(t.predictions[kind].actions).shape == (5, 3, 2)
            assert np.asarray(t.policy_actions).shape == (5, 3, 2)
            assert t.clip_sha256 == clip_sha256(world.scene, world.dt_s, t.browser_payload())
        hashes = {t.predictions["ours"].content_hash for t in world.trials}
        meta = json.loads((bank_dir(small_study.data_dir, small_study.study_id)
                           / "meta.json").read_text())
        assert hashes == {meta["worlds"][name]["checkpoints"]["ours"]["content_hash"]}


def test_build_trials_is_reproducible(small_study, tmp_path):
    data = tmp_path / "var"
    data.mkdir()
    for sub in ("data", "models"):
        (data / sub).symlink_to(small_study.data_dir / sub)
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    path = build_trials(cfg, small_study.study_id, data)
    original = bank_dir(small_study.data_dir, small_study.study_id) / BANK_FILE
    assert sha256_file(path) == sha256_file(original)


def test_predictor_refuses_a_bank_from_other_checkpoints(small_study, bank, tmp_path):
    data = tmp_path / "var"
    data.mkdir()
    (data / "models").symlink_to(small_study.data_dir / "models")
    raw = json.loads(bank_dir(small_study.data_dir, small_study.study_id)
                     .joinpath(BANK_FILE).read_text())
    raw["worlds"]["obstacle"]["trials"][2]["predictions"]["vae"]["actions"][1][2][0] += 0.5
    out = bank_dir(data, small_study.study_id) / BANK_FILE
    out.parent.mkdir(parents=True)
    out.write_text(json.dumps(raw))
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    with pytest.raises(BankMismatch, match="vae answers differ"):
        Predictor(cfg, TrialBank.load(data, small_study.study_id), data)


def test_prepare_skips_what_exists(small_study):
    settings = Settings(data_dir=small_study.data_dir, configs_dir=small_study.configs_dir)
    said = []
    bank = prepare_study(settings, small_study.study_id, say=said.append)
    assert bank_is_current(bank)
    assert sum("skipping" in s for s in said) == 2 + 4 + 1, said


def test_production_mode_refuses_the_default_token(small_study, tmp_path):
    settings = Settings(data_dir=small_study.data_dir, production=True,
                        admin_token=DEFAULT_ADMIN_TOKEN)
    with pytest.raises(UnsafeSettings, match="TOMSTUDY_ADMIN_TOKEN"):
        create_app(settings, [small_study.study_id])
    env = small_study.env(f"sqlite:///{tmp_path / 'x.db'}", TOMSTUDY_PRODUCTION="1",
                          TOMSTUDY_ADMIN_TOKEN=DEFAULT_ADMIN_TOKEN)
    run = subprocess.run([str(Path(sys.executable).parent / "tomstudy"), "serve", "--port", "1"],
                         env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "refusing to start" in run.stderr


def test_in_memory_database_through_dependency_override(small_study, tmp_path):
    engine = create_engine("sqlite://", connect_args={"check_same_thread": False},
                           poolclass=StaticPool)
    create_tables(engine)

    def memory_db():
        with Session(engine) as session:
            yield session

    settings = Settings(data_dir=small_study.data_dir, configs_dir=small_study.configs_dir,
                        database_url=f"sqlite:///{tmp_path / 'unused.db'}")
    app = create_app(settings, [small_study.study_id])
    app.dependency_overrides[get_db] = memory_db
    with TestClient(app) as client:
        r = client.post("/api/sessions", json={"study_id": small_study.study_id})
        token = r.json()["session_token"]
        r = client.post(f"/api/sessions/{token}/consent",
                        json={"submission_id": new_id(), "agree": True})
        assert r.status_code == 200 and r.json()["phase"] == "instructions"
    with Session(engine) as session:
        stored = session.execute(select(Participant)).scalars().one()
    assert stored.position == 1 and stored.recruitment == "anonymous"
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_serve_without_a_bank_says_what_is_missing(small_study, tmp_path):
    env = small_study.env(f"sqlite:///{tmp_path / 'x.db'}", TOMSTUDY_DATA_DIR=str(tmp_path))
    run = subprocess.run([str(Path(sys.executable).parent / "tomstudy"), "serve", "--port", "1",
                          "--study", small_study.study_id],
                         env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert "bank.json" in run.stderr and "--prepare" in run.stderr
