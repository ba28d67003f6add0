"""Names of the worlds and how to build each one from its YAML config."""

from pathlib import Path
from typing import Protocol

import numpy as np

from app.configio import ConfigError, StrictModel, load_yaml_model
from app.data.scene import Scene
from app.data.trajectory import Episode
from app.settings import get_settings

WORLD_NAMES = ("highway", "obstacle")
POLICIES = ("mpc", "sac")


class World(Protocol):
    """What the simulation driver needs from a world."""

    name: str
    dt_s: float
    label_names: dict[str, list[str]]
    robot_label: str  # the label plots colour by and latent metrics score against
    config: StrictModel

    def scene(self) -> Scene: ...

    def rollout(self, rng: np.random.Generator) -> Episode:
        """One episode; raises `Rejected(reason)` when it must not enter the dataset."""
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
