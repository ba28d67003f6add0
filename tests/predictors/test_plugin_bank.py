"""A bank built with `predictors: [ctrv]` stores CTRV's answers, its bundle records the plug-in,
and a server refuses a bank whose plug-in answers it cannot reproduce, naming the plug-in."""

import json
import subprocess

import numpy as np
import pytest

from app.bank.model_answers import BankMismatch, ModelAnswers, trial_inputs
from app.bank.verify import open_bundle
from app.core.contracts import COARSE_OBSERVERS
from app.predictors.builtin import CheckpointPredictor, ConstantVelocity
from app.predictors.ctrv import CTRV
from app.predictors.protocol import ask
from app.study.trials import NO_SEED, TrialBank
from tests.bank.bundles import bundle_root, copied, refrozen_each_trial
from tests.conftest import TOMSTUDY, patience


def test_the_bank_stores_ctrvs_answer_to_every_trial(ctrv_study):
    bank = TrialBank.load(ctrv_study.layout, ctrv_study.study_id)
    trials = list(bank.by_id.values())
    assert {t.world for t in trials} == {"highway", "obstacle"} and len(trials) > 10
    for trial in trials:
        assert sorted(trial.predictions) == sorted(["ctrv", *COARSE_OBSERVERS, "ours", "vae"])
        (stored,) = trial.predictions["ctrv"]
        answer = ask(CTRV(), *trial_inputs(bank, trial))
        assert stored.seed == NO_SEED and stored.code == -1 and stored.z == []
        assert stored.content_hash == CTRV().content_hash
        assert stored.actions == np.round(answer.actions, 5).tolist()
        cv = ask(ConstantVelocity(), *trial_inputs(bank, trial))
        assert trial.cv_actions == np.round(cv.actions, 5).tolist()


def test_the_checkpoints_answer_through_the_protocol_as_stored(ctrv_study):
    bundle = open_bundle(bundle_root(ctrv_study))
    trial = bundle.bank.trials_of("obstacle", "main")[0]
    for name in ("ours", "vae"):
        stored = trial.predictions[name][0]
        model = bundle.model("obstacle", name, stored.seed)
        answer = ask(CheckpointPredictor(model), *trial_inputs(bundle.bank, trial))
        z, code, actions = model.trial(np.asarray(trial.model_input),
                                       np.asarray(trial_inputs(bundle.bank, trial)[1]))
        assert answer.code == code == stored.code and answer.z == [float(v) for v in z]
        np.testing.assert_array_equal(answer.actions, actions)


def test_the_small_study_without_predictors_stores_the_models_and_observers(small_study):
    bank = TrialBank.load(small_study.layout, small_study.study_id)
    assert all(sorted(t.predictions) == sorted([*COARSE_OBSERVERS, "ours", "vae"])
               for t in bank.by_id.values())
    assert "predictors" not in open_bundle(bundle_root(small_study)).manifest


def test_the_manifest_records_the_plugin_and_the_server_recomputes_it(ctrv_study):
    bundle = open_bundle(bundle_root(ctrv_study))
    assert bundle.plugins == {"ctrv": {"content_hash": CTRV().content_hash,
                                       "distribution": "tomstudy", "version": "0.1.0"}}
    answers = ModelAnswers(bundle)
    checks = {(c.world, c.model): c for c in answers.agreements if c.model == "ctrv"}
    assert set(checks) == {("highway", "ctrv"), ("obstacle", "ctrv")}
    assert all(c.ok and c.seed == NO_SEED and c.answers == len(bundle.bank.world(c.world).trials)
               for c in checks.values())
    trial = bundle.bank.trials_of("highway", "main")[0]
    served = answers.answers(trial.trial_id)["ctrv"]
    assert served.content_hash == CTRV().content_hash and served.code == -1
    assert np.round(served.actions, 5).tolist() == trial.predictions["ctrv"][0].actions


def verify(study) -> subprocess.CompletedProcess:
    return subprocess.run([TOMSTUDY, "bundle", "verify", "--study", study.study_id],
                          env=study.env("sqlite://"), capture_output=True, text=True,
                          timeout=patience(120))


def test_a_server_refuses_plugin_answers_it_does_not_reproduce(ctrv_study, tmp_path):
    study = copied(ctrv_study, tmp_path)

    def turn(trial):  # every CTRV move turned by 90 degrees
        for start in trial["predictions"]["ctrv"][0]["actions"]:
            for step in start:
                step[:] = [-step[1], step[0]]

    refrozen_each_trial(study, turn)
    with pytest.raises(BankMismatch, match="highway/ctrv: answers differ from the bank's"):
        ModelAnswers(open_bundle(bundle_root(study)))
    run = verify(study)
    rows = [line.split() for line in run.stdout.splitlines()]
    verdicts = {(r[0], r[1]): r[-1] for r in rows if len(r) == 8 and r[2] == "-"}
    assert run.returncode == 1
    assert verdicts == {("highway", "ctrv"): "MISMATCH", ("obstacle", "ctrv"): "MISMATCH"} | {
        (world, name): "ok" for world in ("highway", "obstacle") for name in COARSE_OBSERVERS}
    assert "plug-in ctrv: frozen with tomstudy 0.1.0" in run.stdout


def test_a_server_refuses_a_bank_whose_plugin_is_not_installed(ctrv_study, tmp_path):
    study = copied(ctrv_study, tmp_path)

    def rename(trial):  # the answers of a plug-in this machine does not have
        trial["predictions"]["labmove"] = trial["predictions"].pop("ctrv")

    refrozen_each_trial(study, rename)
    with pytest.raises(BankMismatch, match=r"highway/labmove: predictor labmove: not installed "
                                           r"\(no entry point 'labmove' in group "
                                           r"tomstudy.predictors; registered: ctrv\)"):
        ModelAnswers(open_bundle(bundle_root(study)))


def test_bundle_verify_passes_the_plugin_study(ctrv_study):
    run = verify(ctrv_study)
    assert run.returncode == 0, run.stdout + run.stderr
    rows = [line.split() for line in run.stdout.splitlines()]
    assert {(r[0], r[1], r[-1]) for r in rows if len(r) == 8 and r[2] == "-"} == {
        (world, name, "ok") for world in ("highway", "obstacle")
        for name in ("ctrv", *COARSE_OBSERVERS)}


def test_a_plugin_changes_nothing_else_in_the_bank(ctrv_study, small_study):
    """Same clips, start states, arms and model answers as the study without it: trial
    selection (the models_disagree arm) reads Ours and the VAE only."""
    with_ctrv = json.loads(ctrv_study.layout.bank(ctrv_study.study_id).read_text())
    without = json.loads(small_study.layout.bank(small_study.study_id).read_text())
    arms = [t["arm"] for w in with_ctrv["worlds"].values() for t in w["trials"]]
    assert "models_disagree" in arms and "random" in arms
    for world in with_ctrv["worlds"].values():
        for trial in world["trials"]:
            assert trial["predictions"].pop("ctrv")
    assert with_ctrv | {"study_id": "small_study"} == without
