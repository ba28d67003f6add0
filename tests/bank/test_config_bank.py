"""The study config, the trial bank (start states on the data, their count and kinds, the
selection arms and the model family's answers), production refusal."""

import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from sqlalchemy.pool import StaticPool
from sqlmodel import Session, create_engine, select

from app.bank.build import (
    build_trials,
    main_trials,
    model_disagreement,
)
from app.bank.start_states import NoStartStates, take_turns
from app.configio import ConfigError, load_yaml_model
from app.core.contracts import SMALLEST_EFFECT_OF_INTEREST
from app.core.files import sha256_file
from app.http.deps import get_db
from app.layout import Layout
from app.main import UnsafeSettings, create_app
from app.observers.family import GOAL_VARIANTS
from app.server.storage.db import create_tables
from app.server.storage.tables import Participant
from app.settings import Settings
from app.study.config import (
    MainTrialSelection,
    StudyConfig,
    bank_design,
    config_sha256,
    load_study_config,
)
from app.study.trials import TrialBank, clip_sha256
from tests.conftest import REPO, TOMSTUDY, SmallStudy, build_bundle_of, local_client, patience
from tests.server import flow
from tests.server.flow import ADMIN, new_id, prediction_body, prolific


def test_paper_study_config_matches_the_paper():
    cfg = load_study_config(Settings(), "paper_study")
    assert cfg.worlds == ["highway", "obstacle"] and cfg.counterbalance_world_order
    assert (cfg.trials_per_world, cfg.examples_per_trial, cfg.start_states,
            cfg.steps_to_predict) == (10, 4, 5, 3)
    assert cfg.target_sample_size == 30  # 22 misses the design goal (docs/reproduce/instrument.md)
    assert (cfg.segment_steps.min, cfg.segment_steps.max) == (5, 7)
    assert cfg.recruitment.platform == "prolific"


@pytest.mark.parametrize("change, field", [
    ({"titel": "x"}, "titel"),
    ({"trials_per_world": -1}, "trials_per_world"),
    ({"segment_steps": {"min": 7, "max": 5}}, "segment_steps"),
    ({"worlds": ["highway", "Mars!"]}, "worlds.1"),
    ({"recruitment": {"completion_code": "X", "prolific_url": "u"}}, "recruitment.prolific_url"),
    ({"recruitment": {"completion_code": "X", "platform": "email"}}, "recruitment.platform"),
    ({"recruitment": {"completion_code": "X", "prolific_redirect_url": "https://p/?cc={code}"}},
     "recruitment: .*prolific_redirect_url: only the placeholder"),
    ({"recruitment": {"completion_code": "X", "mturk_redirect_url": "http://x/{completion_code}"}},
     "recruitment: .*mturk_redirect_url: must be empty or an https"),
    ({"smallest_effect_of_interest": 0}, "smallest_effect_of_interest"),
    ({"smallest_effect_of_interest": 2.5}, "smallest_effect_of_interest"),
])
def test_config_errors_name_the_key(tmp_path, change, field):
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    data.update(change)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=f"bad.yaml: {field}"):
        load_yaml_model(path, StudyConfig)


def test_the_smallest_effect_of_interest_leaves_the_hash_and_the_bank_as_they_were():
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    paper = StudyConfig.model_validate(data)
    assert paper.smallest_effect_of_interest == SMALLEST_EFFECT_OF_INTEREST == 0.005
    del data["smallest_effect_of_interest"]
    before_the_key = StudyConfig.model_validate(data)
    assert "smallest_effect_of_interest" not in paper.model_dump()
    assert config_sha256(paper) == config_sha256(before_the_key)
    assert "exploratory_worlds" in paper.model_dump()  # the other keys' rule still holds
    wider = StudyConfig.model_validate(data | {"smallest_effect_of_interest": 0.01})
    assert wider.model_dump(mode="json")["smallest_effect_of_interest"] == 0.01
    assert config_sha256(wider) != config_sha256(paper)
    assert bank_design(wider.model_dump(mode="json")) == bank_design(data)  # not a design key


def test_a_world_without_its_config_file_is_named(tmp_path):
    from app.settings import Settings
    from app.study.config import load_study_config

    shutil.copytree(REPO / "study_configs" / "worlds", tmp_path / "worlds")
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    data["worlds"] = ["highway", "mars"]
    data["world_intros"]["mars"] = {"title": "Mars", "text": "Red."}
    data.pop("exploratory_worlds")  # names obstacle, which this study no longer has
    (tmp_path / "red.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"red.yaml: worlds.1: no world 'mars': describe it "
                                          r"in .*worlds/mars.yaml \(a recorded world"):
        load_study_config(Settings(configs_dir=tmp_path), "red")


def test_attention_passing_starts_cannot_exceed_the_start_states(tmp_path):
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    data.update(start_states=3, attention_checks={"min_passing_starts": 4})
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match="min_passing_starts must be <= start_states"):
        load_yaml_model(path, StudyConfig)


@pytest.fixture(scope="module")
def bank(small_study) -> TrialBank:
    return TrialBank.load(small_study.layout, small_study.study_id)


def test_bank_trials_have_the_paper_shape(bank, small_study):
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    assert list(bank.data.worlds) == cfg.worlds == ["highway", "obstacle"]
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
            k = cfg.start_states
            starts = np.array([[s.robot, s.human] for s in t.start_states])
            assert starts.shape == (k, 2, 2)
            np.testing.assert_allclose(starts[0], seg[-1])  # robot's own segment end first
            np.testing.assert_allclose(starts[:, 1], np.repeat(seg[-1:, 1], k, 0))  # human fixed
            assert len({tuple(p) for p in starts[:, 0]}) == k
            assert (starts[..., 0] >= b["x_min_m"]).all() and (starts[..., 0] <= b["x_max_m"]).all()
            for kind in ("ours", "vae"):
                assert [a.seed for a in t.predictions[kind]] == cfg.models.seeds
                for answer in t.predictions[kind]:
                    assert np.asarray(answer.actions).shape == (k, 3, 2)
            assert bool(t.arm) == (t.kind == "main")
            assert np.asarray(t.policy_actions).shape == (k, 3, 2)
            assert t.clip_sha256 == clip_sha256(world.scene, world.dt_s, t.browser_payload())
            assert all("start_kind" not in s for s in t.browser_payload()["start_states"])
        meta = json.loads(Layout(small_study.data_dir).bank_meta(small_study.study_id)
                          .read_text())
        for seed_index, seed in enumerate(cfg.models.seeds):
            hashes = {t.predictions["ours"][seed_index].content_hash for t in world.trials}
            assert hashes == {meta["worlds"][name]["checkpoints"][f"ours/seed{seed}"][
                "content_hash"]}
        arms = [t.arm for t in world.trials if t.kind == "main"]
        assert arms == (["random"] * cfg.main_trial_selection.random_arm_trials
                        + ["models_disagree"] * (cfg.bank_trials_per_world
                                                 - cfg.main_trial_selection.random_arm_trials))


OLD_DEFAULT_TOKEN = "change-me-researcher-token"  # the default before issue 22 removed it
DATA_KINDS = {"highway": ("same_lane", "adjacent_lane"), "obstacle": ("near", "mid")}


def learned_robot_states(data_dir: Path, world: str, cfg: StudyConfig) -> np.ndarray:
    """Robot positions of every trajectory outside both checkpoints' test splits."""
    from app.data.trajectory import TrajectorySet
    from app.learning.checkpoint import load_model

    trajs = TrajectorySet.load(data_dir / "data" / world / "trajectories.npz")
    test = set()
    for kind in ("ours", "vae"):
        for seed in cfg.models.seeds:
            model = load_model(Layout(data_dir).checkpoint(world, kind, seed))
            test |= set(model.data_meta["split_trajectories"]["test"])
    return np.concatenate([trajs.positions[i, : trajs.lengths[i] + 1, 0]
                           for i in range(len(trajs)) if i not in test])


def test_start_states_lie_on_the_learned_data_near_the_robot(bank, small_study):
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    reach = cfg.steps_to_predict
    assert set(bank.data.worlds) == {"highway", "obstacle"}
    for name, world in bank.data.worlds.items():
        covered = learned_robot_states(small_study.data_dir, name, cfg)
        r, tol = world.max_step_m, 2e-3  # positions are stored to 1 mm
        counts = dict.fromkeys(DATA_KINDS[name], 0)
        for t in world.trials:
            kinds = [s.start_kind for s in t.start_states]
            robots = np.array([s.robot for s in t.start_states])
            assert kinds[0] == "own"
            assert set(kinds[1:]) <= set(DATA_KINDS[name])  # attention checks too (issue 22)
            for kind in kinds[1:]:
                counts[kind] += 1
            for p in robots[1:]:  # each one a state the models' data covers
                assert np.linalg.norm(covered - p, axis=1).min() < tol
            gaps = np.linalg.norm(robots[:, None] - robots[None], axis=-1)
            assert (gaps[~np.eye(len(robots), dtype=bool)] >= r - tol).all()
            offset = robots[1:] - robots[0]
            if name == "highway":
                lanes = np.array([lane["y_center_m"] for lane in world.scene["lanes"]])
                lane = np.abs(robots[:, 1, None] - lanes).argmin(axis=1)
                assert (np.abs(offset[:, 0]) <= reach * r + tol).all()
                assert [abs(a - lane[0]) for a in lane[1:]] == [
                    0 if k == "same_lane" else 1 for k in kinds[1:]]
            else:
                dist = np.linalg.norm(offset, axis=1)
                assert all(d <= reach * r + tol if k == "near" else reach * r - tol < d
                           <= 2 * reach * r + tol for d, k in zip(dist, kinds[1:], strict=True))
        # both kinds drawn, in turns: the first kind at most one more per trial when both exist
        assert 0 < 4 * min(counts.values()) >= sum(counts.values()), (name, counts)


def test_start_kinds_take_turns_and_fall_back():
    rng = np.random.default_rng(0)
    line = np.array([[x, 0.0] for x in range(1, 30)])
    positions = np.concatenate([line, line + [0, 5]])  # kind a's states, then kind b's
    a, b = np.arange(len(line)), len(line) + np.arange(len(line))
    picks, kinds = take_turns(np.zeros(2), positions, {"a": a, "b": b}, 4, 2.0, rng)
    assert kinds == ["a", "b", "a", "b"]
    assert all((pick in a) == (kind == "a") for pick, kind in zip(picks, kinds, strict=True))
    every = np.array([np.zeros(2), *positions[picks]])
    gaps = np.linalg.norm(every[:, None] - every[None], axis=-1)
    assert gaps[~np.eye(5, dtype=bool)].min() >= 2.0
    none = np.zeros(0, dtype=int)
    _, kinds = take_turns(np.zeros(2), positions, {"a": a, "b": none}, 3, 2.0, rng)
    assert kinds == ["a", "a", "a"]
    with pytest.raises(NoStartStates):
        take_turns(np.zeros(2), positions, {"a": a[:1], "b": a[:1]}, 2, 2.0, rng)


@pytest.fixture(scope="module")
def three_starts(small_study, tmp_path_factory):
    """The small study with `start_states: 3`, its bank built next to the shared data."""
    root = tmp_path_factory.mktemp("three")
    data, configs = root / "var", root / "configs"
    data.mkdir()
    for sub in ("data", "models"):
        (data / sub).symlink_to(small_study.data_dir / sub)
    shutil.copytree(small_study.configs_dir, configs)
    study = yaml.safe_load((configs / f"{small_study.study_id}.yaml").read_text())
    study["start_states"] = 3
    study["attention_checks"]["min_passing_starts"] = 2
    (configs / "three_starts.yaml").write_text(yaml.safe_dump(study))
    build_bundle_of(SmallStudy(data, configs, "three_starts"))
    return data, configs


def test_a_models_disagree_bank_keeps_the_most_controversial_of_its_candidates(small_study,
                                                                             tmp_path):
    data = tmp_path / "var"
    data.mkdir()
    for sub in ("data", "models"):
        (data / sub).symlink_to(small_study.data_dir / sub)
    config = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml",
                             StudyConfig)
    config = config.model_copy(update={"main_trial_selection": MainTrialSelection(
        rule="models_disagree", candidates_per_trial=2)})
    build_trials(config, "controversial", Layout(data))
    meta = json.loads(Layout(data).bank_meta("controversial").read_text())
    bank = TrialBank.load(Layout(data), "controversial")
    assert set(meta["worlds"]) == {"highway", "obstacle"}
    for name, world_meta in meta["worlds"].items():
        selection = world_meta["main_trial_selection"]
        assert selection["candidates"] == 2 * config.bank_trials_per_world
        assert selection["arms"] == {"random": 0, "models_disagree": config.bank_trials_per_world}
        assert selection["ours_vs_vae_models_disagree"] >= selection["ours_vs_vae_candidates"]
        assert len(bank.trials_of(name, "main")) == config.bank_trials_per_world
        assert world_meta["trials"]["attention"] == config.attention_checks.per_world
        checks = world_meta["attention_checks"]  # app/bank/attention.py's account
        assert len(checks["chosen"]) == config.attention_checks.per_world
        assert set(checks["chosen"][0]["pass_probability"]) == set(GOAL_VARIANTS)


def test_random_selection_takes_one_candidate_per_trial_and_has_one_arm():
    with pytest.raises(ValueError, match="candidates_per_trial: must be 1 with rule random"):
        MainTrialSelection(rule="random", candidates_per_trial=2)
    with pytest.raises(ValueError, match="random_arm_trials: only with rule models_disagree"):
        MainTrialSelection(rule="random", random_arm_trials=3)
    assert MainTrialSelection().arm_sizes(30) == {"random": 30}
    assert MainTrialSelection(rule="models_disagree", random_arm_trials=12).arm_sizes(30) == {
        "random": 12, "models_disagree": 18}


def test_the_random_arm_cannot_exceed_the_bank(tmp_path):
    data = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    data["main_trial_selection"]["random_arm_trials"] = data["bank_trials_per_world"] + 1
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match="random_arm_trials must be <= bank_trials_per_world"):
        load_yaml_model(path, StudyConfig)


def test_start_states_config_sets_the_count_and_the_api_follows(three_starts, tmp_path):
    data, configs = three_starts
    bank = TrialBank.load(Layout(data), "three_starts")
    assert set(bank.data.worlds) == {"highway", "obstacle"}
    assert all(world.trials for world in bank.data.worlds.values())
    for name, world in bank.data.worlds.items():
        for t in world.trials:
            assert len(t.start_states) == 3
            assert np.asarray(t.policy_actions).shape[0] == 3
            if t.kind != "attention":
                assert [s.start_kind for s in t.start_states] == ["own", *DATA_KINDS[name]]
    settings = SmallStudy(data, configs).settings(f"sqlite:///{tmp_path / 'study.db'}")
    with local_client(create_app(settings, ["three_starts"])) as client:
        p = flow.Participant(client, "three_starts")
        p.start()
        trial = p.pass_intro()["step"]
        assert len(trial["start_states"]) == 3
        good = prediction_body(trial)
        four = dict(prediction_body(dict(trial, start_states=trial["start_states"] * 2)),
                    points=good["points"] + good["points"][:1])
        r = p.post("predictions", four)
        assert r.status_code == 422 and "points: expected 3 start states" in r.json()["detail"]
        assert p.post("predictions", good).status_code == 201
        r = client.get("/api/researcher/export.csv?study_id=three_starts", headers=ADMIN)
    frame = pd.read_csv(io.StringIO(r.text))
    assert len(frame) == 3 * 3
    stored = bank.by_id[frame["trial_id"].iloc[0]].start_states
    assert list(frame["start_kind"].iloc[::3]) == [s.start_kind for s in stored]


def test_build_trials_is_reproducible(small_study, tmp_path):
    data = tmp_path / "var"
    data.mkdir()
    for sub in ("data", "models"):
        (data / sub).symlink_to(small_study.data_dir / sub)
    cfg = load_yaml_model(small_study.configs_dir / f"{small_study.study_id}.yaml", StudyConfig)
    path = build_trials(cfg, small_study.study_id, Layout(data))
    original = Layout(small_study.data_dir).bank(small_study.study_id)
    assert sha256_file(path) == sha256_file(original)


def test_models_disagree_keeps_the_most_controversial_trials_per_label(small_study):
    bank = TrialBank.load(small_study.layout, small_study.study_id)
    pool = bank.trials_of("obstacle", "main")
    kept = main_trials(pool, {"random": 1, "models_disagree": 3},
                       [model_disagreement(t) for t in pool[1:]])
    assert [t.arm for t in kept] == ["random"] + ["models_disagree"] * 3
    assert kept[0].trial_id == pool[0].trial_id  # the random arm: the pool's first
    rest, disputed = pool[1:], kept[1:]
    labels = sorted({t.robot_label for t in rest})
    for label in labels:
        mine = sorted((model_disagreement(t) for t in rest if t.robot_label == label),
                      reverse=True)
        taken = [model_disagreement(t) for t in disputed if t.robot_label == label]
        assert taken == mine[:len(taken)]  # within a label, the most controversial first
    counts = [sum(t.robot_label == label for t in disputed) for label in labels]
    assert max(counts) - min(counts) <= 1  # labels take turns


def test_family_disagreement_is_the_mean_over_every_ours_and_vae_seed(bank):
    from app.core.alignment import alignment_error

    trial = bank.trials_of("highway", "main")[0]
    pairs = [alignment_error(np.asarray(o.actions), np.asarray(v.actions)).mean()
             for o in trial.predictions["ours"] for v in trial.predictions["vae"]]
    assert len(pairs) == len(trial.predictions["ours"]) ** 2 == 4
    assert model_disagreement(trial) == pytest.approx(np.mean(pairs))


@pytest.mark.parametrize("token", ["", OLD_DEFAULT_TOKEN])
def test_production_mode_refuses_an_unset_or_old_default_token(small_study, tmp_path, token):
    settings = Settings(data_dir=small_study.data_dir, production=True, admin_token=token)
    with pytest.raises(UnsafeSettings, match="TOMSTUDY_ADMIN_TOKEN"):
        create_app(settings, [small_study.study_id])
    env = small_study.env(f"sqlite:///{tmp_path / 'x.db'}", TOMSTUDY_PRODUCTION="1",
                          TOMSTUDY_ADMIN_TOKEN=token)
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1"],
                         env=env, capture_output=True, text=True, timeout=patience(60))
    assert run.returncode == 2 and "refusing to start" in run.stderr


def test_in_memory_database_through_dependency_override(small_study, tmp_path):
    engine = create_engine("sqlite://", connect_args={"check_same_thread": False},
                           poolclass=StaticPool)
    create_tables(engine)

    def memory_db():
        with Session(engine) as session:
            yield session

    settings = small_study.settings(f"sqlite:///{tmp_path / 'unused.db'}")
    app = create_app(settings, [small_study.study_id])
    app.dependency_overrides[get_db] = memory_db
    with local_client(app) as client:
        r = client.post("/api/sessions", json={"study_id": small_study.study_id,
                                               "recruitment": prolific("memory")})
        r = client.post("/api/session/consent", json={"submission_id": new_id(), "agree": True},
                        headers={"X-Session-Token": r.json()["session_token"]})
        assert r.status_code == 200 and r.json()["phase"] == "instructions"
    with Session(engine) as session:
        stored = session.execute(select(Participant)).scalars().one()
    assert stored.position == 1 and stored.recruitment == "prolific"
    shutil.rmtree(tmp_path, ignore_errors=True)

