"""The shared building blocks: reproducible files, typed configs, the MPC sampler, containers."""

import numpy as np
import pytest

from app.configio import ConfigError, StrictModel, load_yaml_model
from app.core.files import atomic_path, sha256_file, write_npz
from app.data.scene import AgentShape, Bounds, Scene
from app.data.trajectory import Episode, TrajectorySet
from app.worlds.mpc import SamplingMPC


class _Cfg(StrictModel):
    dt_s: float
    n_lanes: int


def test_write_npz_is_byte_reproducible(tmp_path):
    arrays = {"b": np.arange(5.0), "a": np.eye(2, dtype=np.float32)}
    write_npz(tmp_path / "one.npz", arrays)
    write_npz(tmp_path / "two.npz", dict(reversed(arrays.items())))
    assert sha256_file(tmp_path / "one.npz") == sha256_file(tmp_path / "two.npz")
    with np.load(tmp_path / "one.npz") as npz:
        np.testing.assert_array_equal(npz["b"], arrays["b"])


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.bin"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_config_typo_names_the_field(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("dt_s: 0.5\nn_lane: 3\n")
    with pytest.raises(ConfigError) as err:
        load_yaml_model(path, _Cfg)
    assert "n_lane" in str(err.value) and "n_lanes" in str(err.value)


def test_missing_config_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_yaml_model(tmp_path / "absent.yaml", _Cfg)


def test_mpc_finds_the_minimum_of_a_quadratic():
    mpc = SamplingMPC(horizon=4, n_samples=128, control_low=(-2.0, -2.0),
                      control_high=(2.0, 2.0), iterations=4)
    target = np.array([1.2, -0.7])

    def cost(controls):
        return ((controls - target) ** 2).sum(axis=(1, 2))

    plan = mpc.plan(cost, mpc.initial_plan(), np.random.default_rng(0))
    assert plan.shape == (4, 2)
    np.testing.assert_allclose(plan.mean(axis=0), target, atol=0.15)


def test_trajectory_set_round_trips_and_pads(tmp_path):
    scene = Scene(world="toy", dt_s=0.5, frame="metres", agents=[
        AgentShape(name="robot", kind="disc", length_m=0.5, width_m=0.5, color="#0072B2")],
        bounds=Bounds(x_min_m=0, x_max_m=10, y_min_m=0, y_max_m=10))
    short = Episode(positions=np.zeros((3, 2, 2)), headings=np.zeros((3, 2)),
                    speeds=np.zeros((3, 2)), labels={"goal": 1})
    long = Episode(positions=np.cumsum(np.ones((5, 2, 2)), axis=0), headings=np.zeros((5, 2)),
                   speeds=np.ones((5, 2)), labels={"goal": 0})
    trajs = TrajectorySet.from_episodes("toy", 0.5, [short, long], {"goal": ["a", "b"]}, scene)
    assert trajs.positions.shape == (2, 5, 2, 2)
    assert list(trajs.lengths) == [2, 4]
    np.testing.assert_allclose(trajs.actions[1], 2.0)  # 1 m per 0.5 s step
    np.testing.assert_allclose(trajs.actions[0], 0.0)
    trajs.save(tmp_path / "t.npz")
    back = TrajectorySet.load(tmp_path / "t.npz")
    assert back.scene == scene and back.label_names == {"goal": ["a", "b"]}
    np.testing.assert_array_equal(back.labels["goal"], [1, 0])
