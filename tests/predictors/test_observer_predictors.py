"""The coarse observers answer every bank trial through the predictor protocol: stored in the
bank, recomputed and verified at start-up like a checkpoint, refused when altered, and their
answer is the observer's expected move, not a noisy draw."""

import numpy as np
import pytest

from app.bank.model_answers import BankMismatch, ModelAnswers, trial_inputs
from app.bank.verify import open_bundle
from app.core.contracts import COARSE_OBSERVERS
from app.observers.config import ObserversConfig, default_observers
from app.observers.family import coarse_options
from app.observers.predictor import ObserverPredictor, observer_predictors
from app.predictors.protocol import ask
from app.study.trials import NO_SEED, TrialBank
from tests.bank.bundles import bundle_root, copied, refrozen_each_trial


@pytest.fixture(scope="module")
def observers(small_study):
    """The small study's observers config (a copy of the repository's)."""
    return default_observers(small_study.configs_dir)


def test_every_trial_stores_each_coarse_observers_expected_move(small_study, observers):
    bank = TrialBank.load(small_study.layout, small_study.study_id)
    for trial in bank.by_id.values():
        asked = trial_inputs(bank, trial)
        for predictor in observer_predictors(observers):
            (stored,) = trial.predictions[predictor.name]
            assert stored.seed == NO_SEED and stored.code == -1 and stored.z == []
            assert stored.content_hash == predictor.content_hash
            assert stored.actions == np.round(ask(predictor, *asked).actions, 5).tolist()


def test_the_answer_is_the_posterior_weighted_mean_of_the_intents_walks(small_study, observers):
    bank = TrialBank.load(small_study.layout, small_study.study_id)
    trial = bank.trials_of("obstacle", "main")[0]
    asked = trial_inputs(bank, trial)
    options = coarse_options("coarse", asked[-1], np.asarray(asked[1])[:, 0], observers)
    weights = np.array([w for w, _ in options])
    expected = sum(w * a for w, a in zip(weights / weights.sum(), (a for _, a in options),
                                         strict=True))
    first = ask(ObserverPredictor("coarse", observers), *asked).actions
    np.testing.assert_allclose(first, expected, atol=1e-12)
    np.testing.assert_array_equal(first, ask(ObserverPredictor("coarse", observers),
                                             *asked).actions)  # deterministic


def test_the_hash_follows_the_parameters_not_their_sources(observers):
    base = ObserverPredictor("coarse", observers).content_hash
    dump = observers.model_dump()

    def with_beta(**change) -> ObserversConfig:
        beta = dump["inference"]["beta"] | change
        return ObserversConfig.model_validate(
            dump | {"inference": dump["inference"] | {"beta": beta}})

    reworded = with_beta(source="another citation for the same value")
    steeper = with_beta(value=3.0)
    assert ObserverPredictor("coarse", reworded).content_hash == base
    assert ObserverPredictor("coarse", steeper).content_hash != base
    assert len({p.content_hash for p in observer_predictors(observers)}) == len(COARSE_OBSERVERS)


def test_an_observer_needs_the_trial_as_shown(small_study, observers):
    bank = TrialBank.load(small_study.layout, small_study.study_id)
    trial = bank.trials_of("highway", "main")[0]
    with pytest.raises(ValueError, match="coarse_scene: reads the scene"):
        ObserverPredictor("coarse_scene", observers).answer(*trial_inputs(bank, trial)[:5])
    with pytest.raises(ValueError, match="observer 'precise': not one of"):
        ObserverPredictor("precise", observers)


def test_the_server_verifies_the_observers_and_refuses_altered_answers(small_study, tmp_path,
                                                                      observers):
    bundle = open_bundle(bundle_root(small_study))
    assert bundle.manifest["observers"] == {p.name: p.content_hash
                                            for p in observer_predictors(observers)}
    answers = ModelAnswers(bundle)
    checks = [c for c in answers.agreements if c.model in COARSE_OBSERVERS]
    assert len(checks) == 2 * len(COARSE_OBSERVERS) and all(c.ok and c.answers for c in checks)
    study = copied(small_study, tmp_path)

    def reverse(trial):  # every coarse_momentum move turned round
        for start in trial["predictions"]["coarse_momentum"][0]["actions"]:
            for step in start:
                step[:] = [-step[0], -step[1]]

    refrozen_each_trial(study, reverse)
    with pytest.raises(BankMismatch, match="highway/coarse_momentum: answers differ"):
        ModelAnswers(open_bundle(bundle_root(study)))
