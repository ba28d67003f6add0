"""Frozen bundles: freezing is reproducible, opening refuses anything the manifest does not
vouch for, the server recomputes every seed's answers, `bundle verify` and `bundle build`
report what they find, and the paper study's shipped bundle verifies on this machine."""

import gzip
import json
import shutil
import subprocess

import pytest
import yaml

from app.bank.bundle import BANK, MANIFEST, BundleError, checkpoint_file, shipped_dir
from app.bank.bundle_diff import compare_bundles
from app.bank.freeze import freeze
from app.bank.model_answers import BankMismatch, ModelAnswers
from app.bank.prepare import bank_is_current, build_bundle, prepare_study
from app.bank.verify import load_bundle, open_bundle
from app.configio import load_yaml_model
from app.layout import Layout
from app.settings import Settings
from app.study.config import StudyConfig, load_study_config
from tests.bank.bundles import bundle_root, copied, refrozen_with
from tests.conftest import (
    REPO,
    SMALL_SEEDS,
    TOMSTUDY,
    SmallStudy,
    patience,
)


def config_of(study: SmallStudy) -> StudyConfig:
    """The study's validated config, read now (load_study_config caches by path)."""
    return load_yaml_model(study.configs_dir / f"{study.study_id}.yaml", StudyConfig)


def test_a_bundle_holds_every_seed_and_freezes_to_the_same_content(small_study, tmp_path):
    bundle = open_bundle(bundle_root(small_study))
    files = bundle.manifest["files"]
    for world in ("highway", "obstacle"):
        for model in ("ours", "vae"):
            for seed in SMALL_SEEDS:
                assert checkpoint_file(world, model, seed) in files
                assert bundle.model(world, model, seed).content_hash == \
                    bundle.manifest["models"][world][model][str(seed)]
    assert {"configs/small_study.yaml", "configs/training.yaml", BANK} <= set(files)
    assert str(small_study.data_dir) not in (bundle.root / "bank_meta.json").read_text()
    again = freeze(config_of(small_study), small_study.study_id, small_study.configs_dir,
                   small_study.layout, tmp_path / "again")
    assert again.manifest["files"] == bundle.manifest["files"]  # gzip without name or time
    assert again.manifest["content_sha256"] == bundle.manifest["content_sha256"]


@pytest.mark.parametrize("damage, message", [
    (lambda root: (root / BANK).write_bytes(gzip.compress(b"{}", mtime=0)), "altered"),
    (lambda root: (root / checkpoint_file("obstacle", "vae", 1)).unlink(),
     "listed in the manifest but missing"),
    (lambda root: (root / "models" / "notes.txt").write_text("x"), "not in the manifest"),
])
def test_opening_refuses_what_the_manifest_does_not_vouch_for(small_study, tmp_path, damage,
                                                               message):
    study = copied(small_study, tmp_path)
    damage(bundle_root(study))
    with pytest.raises(BundleError, match=message):
        open_bundle(bundle_root(study))


def test_the_server_refuses_a_bundle_whose_config_shapes_another_bank(small_study, tmp_path):
    study = copied(small_study, tmp_path)
    path = study.configs_dir / f"{study.study_id}.yaml"
    raw = yaml.safe_load(path.read_text())
    path.write_text(yaml.safe_dump(raw | {"title": "renamed", "description": "new words"}))
    load_bundle(config_of(study), study.study_id, study.configs_dir, study.layout)
    path.write_text(yaml.safe_dump(raw | {"bank_seed": 7, "models": {"seeds": [0]}}))
    with pytest.raises(BundleError, match="bank_seed, models"):
        load_bundle(config_of(study), study.study_id, study.configs_dir, study.layout)
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1", "--study", study.study_id],
                         env=study.env(f"sqlite:///{tmp_path / 'x.db'}"), capture_output=True,
                         text=True, timeout=patience(120))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "what shapes the trial bank: bank_seed, models" in run.stderr


def test_serving_without_a_bundle_says_how_to_build_it(small_study, tmp_path):
    env = small_study.env(f"sqlite:///{tmp_path / 'x.db'}", TOMSTUDY_DATA_DIR=str(tmp_path))
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1", "--study", small_study.study_id],
                         env=env, capture_output=True, text=True, timeout=patience(120))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "no bundle of study small_study" in run.stderr
    assert "tomstudy bundle build --study small_study" in run.stderr


def training_rows(stdout: str) -> dict:
    """`bundle verify`'s training table: (world, model, seed) -> (epochs run, cap, converged)."""
    lines = stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[-1:] == ["training"])
    rows = {}
    for cells in (line.split() for line in lines[start + 1:]):
        if len(cells) < 7 or not cells[2].isdigit():
            break
        rows[(cells[0], cells[1], int(cells[2]))] = (int(cells[3]), int(cells[5]),
                                                     cells[6] == "converged")
    return rows


def test_model_answers_refuse_stored_answers_their_checkpoint_does_not_give(small_study,
                                                                           tmp_path):
    study = copied(small_study, tmp_path)

    def nudge(raw):
        raw["worlds"]["obstacle"]["trials"][2]["predictions"]["vae"][1]["actions"][1][2][0] += 0.5

    refrozen_with(study, nudge)
    bundle = open_bundle(bundle_root(study))  # the manifest vouches for the new bank
    with pytest.raises(BankMismatch, match="obstacle/vae seed 1: answers differ"):
        ModelAnswers(bundle)
    run = subprocess.run([TOMSTUDY, "bundle", "verify", "--study", study.study_id],
                         env=study.env("sqlite://"), capture_output=True, text=True,
                         timeout=patience(120))
    assert run.returncode == 1
    rows = [line.split() for line in run.stdout.splitlines()]
    verdicts = {(r[0], r[1], r[2]): r[-1] for r in rows if len(r) == 8 and r[2].isdigit()}
    assert verdicts.pop(("obstacle", "vae", "1")) == "MISMATCH"
    assert set(verdicts.values()) == {"ok"} and len(verdicts) == 2 * 2 * len(SMALL_SEEDS) - 1


def test_bundle_verify_recomputes_every_seed_of_every_model(small_study):
    run = subprocess.run([TOMSTUDY, "bundle", "verify", "--study", small_study.study_id],
                         env=small_study.env("sqlite://"), capture_output=True, text=True,
                         timeout=patience(120))
    assert run.returncode == 0, run.stderr
    rows = [line.split() for line in run.stdout.splitlines()]
    checked = [r for r in rows if len(r) == 8 and r[2].isdigit()]
    assert {(r[0], r[1], int(r[2])) for r in checked} == {
        (w, m, s) for w in ("highway", "obstacle") for m in ("ours", "vae") for s in SMALL_SEEDS}
    bank = open_bundle(bundle_root(small_study)).bank
    assert all(int(r[3]) == len(bank.world(r[0]).trials) and r[-1] == "ok" for r in checked)
    # the small study trains 2 epochs with a patience of 2: every checkpoint hits its cap
    assert training_rows(run.stdout) == {(r[0], r[1], int(r[2])): (2, 2, False)
                                         for r in checked}
    assert "NOT CONVERGED (hit the cap)" in run.stdout


def test_a_changed_answer_shows_in_the_comparison_of_two_bundles(small_study, tmp_path):
    study = copied(small_study, tmp_path)

    def turn(raw):  # the first start state's first Ours seed-0 move, turned by 90 degrees
        vx, vy = raw["worlds"]["highway"]["trials"][0]["predictions"]["ours"][0]["actions"][0][0]
        raw["worlds"]["highway"]["trials"][0]["predictions"]["ours"][0]["actions"][0][0] = [-vy,
                                                                                           vx]

    refrozen_with(study, turn)
    diff = compare_bundles(open_bundle(bundle_root(small_study)), open_bundle(bundle_root(study)))
    assert not diff["content_same"] and diff["files"]["changed"] == [BANK]
    assert all(row["same"] and row["same_weights"] and not row["other_keys_differ"]
               for row in diff["checkpoints"])
    gaps = {(r["model"], r["seed"]): r for r in diff["worlds"]["highway"]["answers"]}
    assert gaps[("ours", 0)]["max_degrees"] == pytest.approx(90.0, abs=1e-3)
    assert gaps[("ours", 1)]["max_degrees"] < 1e-5 and gaps[("vae", 0)]["max_metres"] == 0.0
    assert diff["worlds"]["highway"]["trials_same_clip"] == len(
        open_bundle(bundle_root(study)).bank.world("highway").trials)


def test_build_bundle_skips_what_exists_and_refreezes(small_study, tmp_path):
    study = copied(small_study, tmp_path)
    settings = Settings(data_dir=study.data_dir, configs_dir=study.configs_dir)
    said = []
    bundle = build_bundle(settings, study.study_id, say=said.append)
    assert sum("skipping" in s for s in said) == 2 + 1, said  # two worlds' data, the bank
    assert [s for s in said if s.startswith("training")] == [
        f"training 0 {m} checkpoint(s) on 2 process(es); 4 already exist"
        for m in ("ours", "vae")]
    assert bundle.bank.sha256 == open_bundle(bundle_root(small_study)).bank.sha256
    checkpoints = [(w, m, s) for w in ("highway", "obstacle") for m in ("ours", "vae")
                   for s in SMALL_SEEDS]
    assert [(r["world"], r["model"], r["seed"], r["epochs_run"], r["max_epochs"], r["stopped_by"])
            for r in bundle.manifest["unconverged"]] == [(*c, 2, 2, "cap") for c in checkpoints]
    warned = [s for s in said if s.startswith("WARNING")]
    assert len(warned) == len(checkpoints) and all(
        f"{w}/{m} seed {s} did not converge" in line and "max_epochs 2" in line
        for (w, m, s), line in zip(checkpoints, warned, strict=True))
    config = config_of(study)
    layout = Layout(study.data_dir)
    assert bank_is_current(layout, study.study_id, config)
    assert not bank_is_current(layout, study.study_id, config.model_copy(update={"bank_seed": 3}))
    assert bank_is_current(layout, study.study_id, config.model_copy(update={"title": "renamed"}))
    rescored = config.attention_checks.model_copy(update={"max_angle_deg": 30.0})
    assert not bank_is_current(layout, study.study_id,  # a check is fair at its threshold
                               config.model_copy(update={"attention_checks": rescored}))
    retired = config.attention_checks.model_copy(update={"candidate_max_angle_deg": 5.0})
    assert bank_is_current(layout, study.study_id,
                           config.model_copy(update={"attention_checks": retired}))
    said.clear()
    assert prepare_study(settings, study.study_id, say=said.append) == bundle.root
    assert said == [f"serving the built bundle {bundle.root}"]


def test_a_shipped_study_is_served_as_it_is(small_study, tmp_path):
    study = copied(small_study, tmp_path)
    path = study.configs_dir / f"{study.study_id}.yaml"
    path.write_text(yaml.safe_dump(yaml.safe_load(path.read_text()) | {"bundle": "shipped"}))
    shipped = shipped_dir(study.configs_dir, study.study_id)
    shutil.copytree(bundle_root(study), shipped)
    shutil.rmtree(Layout(study.data_dir).bank_dir(study.study_id))
    settings = Settings(data_dir=study.data_dir, configs_dir=study.configs_dir)
    assert prepare_study(settings, study.study_id, say=lambda _: None) == shipped
    bundle = load_bundle(config_of(study), study.study_id, study.configs_dir, study.layout)
    assert bundle.root == shipped


def test_the_paper_studys_shipped_bundle_verifies_on_this_machine():
    config = load_study_config(Settings(), "paper_study")
    assert config.bundle == "shipped" and len(config.models.seeds) >= 5
    root = shipped_dir(REPO / "study_configs", "paper_study")
    assert (root / MANIFEST).is_file()
    assert sum(f["bytes"] for f in json.loads((root / MANIFEST).read_text())[
        "files"].values()) < 8 * 2 ** 20
    run = subprocess.run([TOMSTUDY, "bundle", "verify", "--study", "paper_study"],
                         capture_output=True, text=True, timeout=patience(300), cwd=REPO)
    assert run.returncode == 0, run.stdout + run.stderr
    checked = [r for r in (line.split() for line in run.stdout.splitlines())
               if len(r) == 8 and r[2].isdigit()]
    assert len(checked) == 2 * 2 * len(config.models.seeds)
    assert all(r[-1] == "ok" for r in checked)
    # rebuilt for issue 30: every checkpoint stopped on patience, well under its cap
    training = training_rows(run.stdout)
    assert len(training) == len(checked)
    assert all(converged and epochs < cap for epochs, cap, converged in training.values())


def test_same_weights_tells_weights_from_what_else_a_checkpoint_records(small_study):
    """A from-scratch build on one machine trains the same weights, but an older checkpoint's
    content hash also covers the data's recorded simulation wall time: the comparison says
    which."""
    import copy
    import dataclasses

    model = open_bundle(bundle_root(small_study)).model("highway", "ours", 0)
    timed = dataclasses.replace(model, data_meta=copy.deepcopy(model.data_meta) | {
        "source": {**model.data_meta.get("source", {}), "wall_time_s": 1e6}})
    assert model.same_weights(timed) and timed.data_meta != model.data_meta
    nudged_state = {k: v.clone() for k, v in model._state_dict.items()}  # torch tensors
    first = next(iter(nudged_state))
    nudged_state[first].view(-1)[0] += 1e-3
    assert not model.same_weights(dataclasses.replace(model, _state_dict=nudged_state))
