"""The `World` protocol every world implements, the worlds' names, and how to build each one
from its YAML config (the Obstacle world's SAC policy is wired in here)."""

from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from app.configio import ConfigError, StrictModel, load_yaml_model
from app.data.scene import Scene
from app.data.trajectory import Episode
from app.layout import Layout
from app.settings import get_settings

WORLD_NAMES = ("highway", "obstacle")
POLICIES = ("mpc", "sac")


@runtime_checkable
class World(Protocol):
    """Everything the simulation, the learning and the trial bank need from a world, so
    nothing outside app/worlds/ asks which world it has.

    Shapes: A = 2 agents (0 robot, 1 human), positions in the scene frame [m]; a segment is
    [T+1, A, 2] states, the last one the segment end. Start candidates are computed on the
    `scene` passed in: the one the trajectories were simulated in and the browser shows.
    """

    name: str
    dt_s: float
    label_names: dict[str, list[str]]
    robot_label: str  # the label plots colour by and latent metrics score against
    config: StrictModel

    def scene(self) -> Scene:
        """The world's geometry for plots, the trial bank and the browser."""
        ...

    def prepare(self, layout: Layout) -> None:
        """Per-world set-up before rollouts (e.g. train a learnt policy); may do nothing."""
        ...

    def rollout(self, rng: np.random.Generator) -> Episode:
        """One episode; raises `Rejected(reason)` when it must not enter the dataset."""
        ...

    def robot_policy_actions(self, positions: np.ndarray, robot_heading: float,
                             robot_speed: float, human_velocity: np.ndarray, labels: dict,
                             n_steps: int, rng: np.random.Generator) -> np.ndarray:
        """The robot's own next actions [n_steps, 2] (m/s) from the start state positions
        [A, 2], the human moving at constant velocity."""
        ...

    def visible_ends(self, robot_track: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """The segment ends among `ends` (steps of one trajectory's robot track [L+1, 2])
        where the robot's behaviour is under way but not finished."""
        ...

    def data_start_candidates(self, scene: Scene, segment: np.ndarray, covered: np.ndarray,
                              reach: float) -> dict[str, np.ndarray]:
        """Robot positions from the data `covered` [M, 2] that may start a prediction after
        `segment`, by start kind (the first kind draws first); `reach` = n steps x max step."""
        ...


def default_config_path(world: str) -> Path:
    """study_configs/worlds/<world>.yaml under the configured configs dir."""
    return get_settings().configs_dir / "worlds" / f"{world}.yaml"


def build_world(world: str, config_path: Path | None = None, policy: str = "mpc") -> World:
    """Load the world's typed config and construct it; errors name the field."""
    if world not in WORLD_NAMES:
        raise ConfigError(f"world: unknown world {world!r}; choose one of {', '.join(WORLD_NAMES)}")
    if policy not in POLICIES:
        raise ConfigError(f"policy: unknown policy {policy!r}; choose one of {', '.join(POLICIES)}")
    path = config_path or default_config_path(world)
    if world == "highway":
        if policy != "mpc":
            raise ConfigError("policy: highway supports only 'mpc'")
        from app.worlds.highway import HighwayWorld

        return HighwayWorld.from_yaml(path)
    return build_obstacle_world(path, policy)


def build_obstacle_world(path: Path, policy: str) -> World:
    """The Obstacle world, its agents on the MPC or on the SAC policy passed into it."""
    from app.worlds.obstacle import ObstacleConfig, ObstacleWorld

    config = load_yaml_model(path, ObstacleConfig)
    if policy == "mpc":
        return ObstacleWorld(config)
    from app.worlds.sac import SACPolicy

    return ObstacleWorld(config, agent_policy=SACPolicy(config))
