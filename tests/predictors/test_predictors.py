"""The predictor protocol on the built-ins, and plug-ins found by entry point name."""

import numpy as np
import pytest
from pydantic import ValidationError

from app.predictors import registry
from app.predictors.builtin import ConstantVelocity
from app.predictors.ctrv import CTRV
from app.predictors.protocol import Predictor, PredictorAnswer, ask
from app.predictors.registry import (
    GROUP,
    UnknownPredictor,
    check_names,
    distribution,
    load_predictor,
    registered,
)
from app.study.config import StudyConfig, config_sha256
from tests.predictors.lab_plugin import install_lab_plugin

DT = 0.5


def straight_history(velocity, steps: int = 6) -> np.ndarray:
    """Robot and human positions [steps+1, 2, 2] moving at constant velocities."""
    t = np.arange(steps + 1)[:, None] * DT
    robot = np.array([1.0, 2.0]) + t * np.asarray(velocity)
    human = np.array([5.0, 0.0]) + t * np.array([0.0, 1.0])
    return np.stack([robot, human], axis=1)


def circle(phase: np.ndarray, radius: float = 8.0) -> np.ndarray:
    """Points [len, 2] on a circle of `radius` around (3, -1) at angles `phase`."""
    return np.array([3.0, -1.0]) + radius * np.stack([np.cos(phase), np.sin(phase)], axis=-1)


def starts_at(robots) -> np.ndarray:
    """Start states [K, 2, 2] with the human at a fixed spot."""
    robots = np.asarray(robots, dtype=np.float64)
    return np.stack([robots, np.tile([[5.0, 0.0]], (len(robots), 1))], axis=1)


def test_ctrv_on_a_straight_history_is_constant_velocity():
    velocity = np.array([3.0, 4.0])
    history = straight_history(velocity)
    heading = np.arctan2(velocity[1], velocity[0])
    starts = starts_at([history[-1, 0], [0.0, 0.0]])
    ctrv = ask(CTRV(), history, starts, [heading, heading], DT, 3)
    cv = ask(ConstantVelocity(), history, starts, [heading, heading], DT, 3)
    assert ctrv.code == -1 and ctrv.z == [] and ctrv.actions.shape == (2, 3, 2)
    np.testing.assert_allclose(ctrv.actions, cv.actions, atol=1e-12)
    np.testing.assert_allclose(cv.actions, np.broadcast_to(velocity, (2, 3, 2)), atol=1e-12)
    # from a start heading the other way, the same speed the other way
    turned = ask(CTRV(), history, starts[:1], [heading + np.pi], DT, 3)
    np.testing.assert_allclose(turned.actions, -cv.actions[:1], atol=1e-12)


def test_ctrv_on_a_constant_turn_goes_on_along_the_circle():
    turn_rate, radius = 0.3, 8.0  # rad/s, m: 0.15 rad per step
    phase = 0.2 + turn_rate * DT * np.arange(10)
    points = circle(phase, radius)
    history = np.stack([points[:7], np.zeros((7, 2))], axis=1)
    tangent = phase[6] + np.pi / 2  # the heading of a car driving the circle anticlockwise
    answer = ask(CTRV(), history, starts_at([points[6]]), [tangent], DT, 3)
    truth = np.diff(points[6:10], axis=0) / DT  # the circle's next three steps
    np.testing.assert_allclose(answer.actions[0], truth, atol=1e-12)
    assert not np.allclose(answer.actions[0], truth[0])  # it turns: not constant velocity


def test_content_hashes_follow_parameters_and_versions():
    assert CTRV().content_hash == CTRV().content_hash
    assert CTRV(history_steps=2).content_hash != CTRV().content_hash
    assert CTRV(version="2").content_hash != CTRV().content_hash
    assert ConstantVelocity().content_hash != CTRV().content_hash
    assert isinstance(CTRV(), Predictor) and isinstance(ConstantVelocity(), Predictor)


def test_an_answer_of_the_wrong_shape_is_refused_naming_the_predictor():
    class Short:
        name, content_hash = "short", "0" * 64

        def answer(self, history, starts, headings, dt_s, n_steps):
            return PredictorAnswer(np.zeros((len(starts), n_steps - 1, 2)))

    with pytest.raises(ValueError, match=r"predictor short: actions must have shape \[2, 3, 2\]"):
        ask(Short(), straight_history([1.0, 0.0]), starts_at([[0, 0], [1, 1]]), [0, 0], DT, 3)


def test_ctrv_is_registered_through_the_projects_own_entry_point():
    assert registered()["ctrv"].value == "app.predictors.ctrv:CTRV"
    assert load_predictor("ctrv") == CTRV()
    assert distribution("ctrv")["distribution"] == "tomstudy"


def test_a_labs_installed_package_is_found_by_its_entry_point(tmp_path, monkeypatch):
    with pytest.raises(UnknownPredictor, match="drift: not installed"):
        load_predictor("drift")
    monkeypatch.syspath_prepend(str(install_lab_plugin(tmp_path)))
    assert set(registered()) >= {"ctrv", "drift"}
    drift = load_predictor("drift")
    assert drift.name == "drift" and len(drift.content_hash) == 64
    answer = ask(drift, straight_history([1.0, 0.0]), starts_at([[0, 0]]), [np.pi / 2], DT, 3)
    np.testing.assert_allclose(answer.actions, [[[0.0, 0.25]] * 3], atol=1e-12)
    assert distribution("drift") == {"distribution": "lab_predictors", "version": "0.3.1"}


def test_check_names_scans_the_entry_points_once_a_call(tmp_path, monkeypatch):
    scans = []
    scan = registry.entry_points
    monkeypatch.setattr(registry, "entry_points",
                        lambda **kwargs: scans.append(kwargs) or scan(**kwargs))
    assert check_names([]) == [] and scans == []
    assert check_names(["ctrv"]) == ["ctrv"] and len(scans) == 1
    with pytest.raises(ValueError, match=r"named 'nope' .*registered: ctrv\).*named 'nada'"):
        check_names(["nope", "ctrv", "nada"])
    assert scans == [{"group": GROUP}] * 2
    monkeypatch.syspath_prepend(str(install_lab_plugin(tmp_path)))  # no cache between calls
    assert check_names(["drift", "ctrv"]) == ["drift", "ctrv"] and len(scans) == 3


def test_an_entry_point_that_makes_another_name_is_refused(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(install_lab_plugin(tmp_path, name="wrongname",
                                                       factory="StandStill")))
    (tmp_path / "lab_predictors" / "__init__.py").write_text(
        (tmp_path / "lab_predictors" / "__init__.py").read_text()
        .replace('name = "wrongname"', 'name = "other"'))
    with pytest.raises(TypeError, match="does not make a predictor named 'wrongname'"):
        load_predictor("wrongname")


def paper_config() -> dict:
    from app.configio import load_yaml_model
    from tests.conftest import REPO

    return load_yaml_model(REPO / "study_configs" / "paper_study.yaml",
                           StudyConfig).model_dump(mode="json")


def test_a_study_config_names_registered_predictors_only():
    config = paper_config()
    assert "predictors" not in config  # a study without plug-ins dumps as before
    with_ctrv = StudyConfig.model_validate(config | {"predictors": ["ctrv"]})
    assert with_ctrv.predictors == ["ctrv"]
    assert config_sha256(with_ctrv) != config_sha256(StudyConfig.model_validate(config))
    for names, message in ((["nope"], "no installed predictor is named 'nope'"),
                           (["vae"], "'vae' is one of the study's own predictors"),
                           (["human"], "'human' is one of the study's own predictors"),
                           (["participant"], "'participant' is one of the study's own"),
                           (["policy"], "'policy' is one of the study's own predictors"),
                           (["ctrv", "ctrv"], "each predictor may be named once"),
                           (["Bad-Name"], "is not a predictor name")):
        with pytest.raises(ValidationError) as err:
            StudyConfig.model_validate(config | {"predictors": names})
        problem = err.value.errors()[0]
        assert problem["loc"] == ("predictors",) and message in problem["msg"], problem
    with pytest.raises(ValidationError, match=f"group {GROUP}; registered: ctrv"):
        StudyConfig.model_validate(config | {"predictors": ["nope"]})
