"""Obstacle world: typed config, geometry of kept rollouts, labels, determinism, SAC policy."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from app.configio import ConfigError
from app.data.trajectory import HUMAN, ROBOT, TrajectorySet
from app.layout import Layout
from app.settings import REPO_ROOT
from app.worlds.obstacle import ObstacleConfig, ObstacleWorld
from app.worlds.registry import build_world
from app.worlds.simulate import episode_rng, simulate

CONFIG = REPO_ROOT / "study_configs" / "worlds" / "obstacle.yaml"
N_SMALL = 40


def write_config(path: Path, edit) -> Path:
    """The real obstacle.yaml with `edit(dict)` applied."""
    data = yaml.safe_load(CONFIG.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def world() -> ObstacleWorld:
    return ObstacleWorld.from_yaml(CONFIG)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> TrajectorySet:
    out = tmp_path_factory.mktemp("obstacle")
    result = simulate("obstacle", N_SMALL, 0, Layout(out), CONFIG, workers=1)
    return TrajectorySet.load(result.npz_path)


def test_misspelt_key_names_the_field(tmp_path):
    def misspell(data):
        data["max_sped_mps"] = data.pop("max_speed_mps")

    with pytest.raises(ConfigError, match="max_sped_mps"):
        ObstacleWorld.from_yaml(write_config(tmp_path / "w.yaml", misspell))


def test_bad_nested_value_names_the_field(tmp_path):
    def negative_radius(data):
        data["obstacles"][1]["radius_m"] = -1.0

    with pytest.raises(ConfigError, match=r"obstacles\.1\.radius_m"):
        ObstacleWorld.from_yaml(write_config(tmp_path / "w.yaml", negative_radius))


def test_geodesic_distance_goes_around_obstacles(world):
    goal = 2  # bottom-left
    g = np.array([world.config.goals[goal].x_m, world.config.goals[goal].y_m])
    obs = world.config.obstacles[2]
    centre = np.array([obs.x_m, obs.y_m])
    away = (centre - g) / np.linalg.norm(centre - g)
    hidden = centre + (obs.radius_m + 0.5) * away  # straight line to the goal hits the obstacle
    straight = np.linalg.norm(hidden - g)
    assert straight + 0.1 < world.fields.distance(goal, hidden) < 1.5 * straight
    in_open = np.array([1.0, 5.0])  # straight down the free left edge
    assert world.fields.distance(goal, in_open) == pytest.approx(4.0, rel=0.03)


def test_kept_rollouts_never_collide_or_leave_the_plane(world, small_run):
    c = world.config
    r = c.agent_radius_m
    assert len(small_run) == N_SMALL
    for i in range(len(small_run)):
        pos = small_run.positions[i, : small_run.lengths[i] + 1].astype(np.float64)
        for obs in c.obstacles:
            gap = np.linalg.norm(pos - [obs.x_m, obs.y_m], axis=-1) - obs.radius_m - r
            assert gap.min() > 0, f"trajectory {i} touches an obstacle"
        assert (np.linalg.norm(pos[:, ROBOT] - pos[:, HUMAN], axis=-1) > 2 * r).all()
        assert (pos >= r).all() and (pos[..., 0] <= c.width_m - r).all()
        assert (pos[..., 1] <= c.height_m - r).all()


def test_labels_goals_and_arrival(world, small_run):
    labels, c = small_run.labels, world.config
    assert set(labels["robot_goal"]) == set(range(4))
    assert (labels["robot_goal"] != labels["human_goal"]).all()
    assert (labels["robot_reached_goal"] == 1).all()
    assert small_run.label_names["robot_goal"] == [g.label for g in c.goals]
    for i in range(len(small_run)):
        goal = c.goals[labels["robot_goal"][i]]
        to_goal = np.linalg.norm(small_run.positions[i, :, ROBOT] - [goal.x_m, goal.y_m], axis=-1)
        arrival = labels["robot_arrival_step"][i]
        assert to_goal[small_run.lengths[i]] <= c.goal_radius_m  # ends inside its goal
        assert to_goal[arrival] <= c.goal_radius_m < to_goal[:arrival].min()
        assert (small_run.positions[i, arrival:, ROBOT] == small_run.positions[i, -1, ROBOT]).all()


def test_actions_are_position_differences_within_the_speed_limit(world, small_run):
    expected = np.diff(small_run.positions, axis=1) / small_run.dt_s
    np.testing.assert_allclose(small_run.actions, expected, rtol=1e-6, atol=1e-6)
    speed = np.linalg.norm(small_run.actions, axis=-1)
    assert speed.max() <= world.config.max_speed_mps + 1e-4
    for i, length in enumerate(small_run.lengths):  # speeds are padded after the end
        np.testing.assert_allclose(small_run.speeds[i, 1:length + 1], speed[i, :length],
                                   atol=1e-4)


def test_interactions_last_15_to_30_steps(world, small_run):
    assert small_run.lengths.min() >= 15
    assert small_run.lengths.max() <= world.config.max_steps


def test_same_rng_same_rollout(world):
    a = world.rollout(episode_rng(7, 3, 0))
    b = world.rollout(episode_rng(7, 3, 0))
    np.testing.assert_array_equal(a.positions, b.positions)
    assert a.labels == b.labels


def test_robot_policy_actions_head_for_the_labelled_goal(world, small_run):
    i, t = 0, 5
    labels = {k: int(v[i]) for k, v in small_run.labels.items()}
    state = small_run.positions[i, t].astype(np.float64)
    human_v = (small_run.positions[i, t, HUMAN] - small_run.positions[i, t - 1, HUMAN]) / 0.5
    actions = world.robot_policy_actions(state, float(small_run.headings[i, t, ROBOT]),
                                         float(small_run.speeds[i, t, ROBOT]), human_v, labels,
                                         3, np.random.default_rng(0))
    assert actions.shape == (3, 2)
    assert (np.linalg.norm(actions, axis=-1) <= world.config.max_speed_mps + 1e-9).all()
    end = state[ROBOT] + actions.sum(axis=0) * world.dt_s
    goal = labels["robot_goal"]
    assert world.fields.distance(goal, end) < world.fields.distance(goal, state[ROBOT]) - 0.5


@pytest.mark.slow
def test_sac_policy_trains_saves_and_rolls_out(tmp_path):
    sac = {"total_timesteps": 300, "learning_starts": 100, "batch_size": 32,
           "buffer_size": 1000, "hidden_units": [16, 16], "eval_episodes": 10}

    def tiny_sac(data):
        data["sac"].update(sac)

    config_path = write_config(tmp_path / "w.yaml", tiny_sac)
    world = build_world("obstacle", config_path, policy="sac")
    world.prepare(Layout(tmp_path))
    assert (tmp_path / "policies" / "obstacle_sac.zip").is_file()
    meta = yaml.safe_load((tmp_path / "policies" / "obstacle_sac.meta.json").read_text())
    assert meta["total_timesteps"] == 300 and 0 <= meta["evaluation"]["kept_rate"] <= 1

    goals, starts = world.sample_task(np.random.default_rng(0))
    positions, arrival = world._simulate(starts, np.zeros((2, 2)), goals,
                                         np.random.default_rng(0), 10, check_safety=False)
    assert positions.shape[1:] == (2, 2) and arrival.shape == (2,)
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=-1) / world.dt_s
    assert steps.max() <= world.config.max_speed_mps + 1e-9

    from app.worlds.sac import SACPolicy

    config = ObstacleConfig.model_validate(world.config.model_dump())
    reloaded = ObstacleWorld(config, agent_policy=SACPolicy(config))
    labels = {"robot_goal": int(goals[ROBOT]), "human_goal": int(goals[HUMAN])}
    args = (starts, 0.0, 0.0, np.zeros(2), labels, 3)
    first = world.robot_policy_actions(*args, np.random.default_rng(1))
    again = reloaded.robot_policy_actions(*args, np.random.default_rng(2))
    assert first.shape == (3, 2)
    np.testing.assert_array_equal(first, again)  # deterministic, loaded from the saved file
