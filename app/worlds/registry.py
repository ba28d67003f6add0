"""The `World` protocol every world implements, the worlds' names, and how to build each one
from its YAML config (the Obstacle world's SAC policy is wired in here).

Two kinds: the simulated worlds (Highway, Obstacle: code, rolled out by simulate.py, each
registered in SIMULATED_WORLDS below; docs/extend/add-a-world.md adds one) and recorded worlds
(any study_configs/worlds/<name>.yaml with `kind: recorded`: recordings imported by
app/recordings/importer.py, app/worlds/recorded.py)."""

import re
from collections.abc import Callable
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import yaml

from app.configio import ConfigError, StrictModel, load_yaml_model
from app.data.scene import Scene
from app.data.trajectory import Covered, Episode
from app.layout import Layout
from app.settings import get_settings

RECORDED_KIND = "recorded"
WORLD_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")  # names folders under the data dir


@runtime_checkable
class World(Protocol):
    """Everything the learning, the trial bank and the observers need from a world, so
    nothing outside app/worlds/ asks which world it has (a simulated world also rolls out:
    `SimulatedWorld`).

    Shapes: A = 2 agents (0 robot, 1 human), positions in the scene frame [m]; a segment is
    [T+1, A, 2] states, the last one the segment end. Start candidates are computed on the
    `scene` passed in: the one the trajectories were simulated in and the browser shows.
    """

    name: str
    dt_s: float
    label_names: dict[str, list[str]]
    robot_label: str  # the label plots colour by and latent metrics score against
    config: StrictModel
    # True: a start drawn from the data is that data state (its heading, speed and recorded
    # next moves as the answer); False: the segment end's robot moved there (start_states.py)
    starts_as_recorded: bool

    def prepare(self, layout: Layout) -> None:
        """Per-world set-up before the world rolls out or answers (train a learnt policy, read
        a recorded world's data); may do nothing."""
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

    def data_start_candidates(self, scene: Scene, segment: np.ndarray, covered: Covered,
                              reach: float) -> dict[str, np.ndarray]:
        """Indices into the data `covered` of the robot states that may start a prediction
        after `segment`, by start kind (the first kind draws first); `reach` = n steps x max
        step."""
        ...


@runtime_checkable
class SimulatedWorld(World, Protocol):
    """A world of code: its scene is fixed and its episodes are rolled out."""

    def scene(self) -> Scene:
        """The world's geometry for plots, the trial bank and the browser."""
        ...

    def rollout(self, rng: np.random.Generator) -> Episode:
        """One episode; raises `Rejected(reason)` when it must not enter the dataset."""
        ...


def default_config_path(world: str) -> Path:
    """study_configs/worlds/<world>.yaml under the configured configs dir."""
    return get_settings().configs_dir / "worlds" / f"{world}.yaml"


def is_recorded(world: str, config_path: Path | None = None) -> bool:
    """Whether `world` is a recorded world (its YAML says `kind: recorded`)."""
    if world in SIMULATED_WORLDS:
        return False
    if not WORLD_NAME.fullmatch(world):
        raise ConfigError(f"world: {world!r} is not a world name (lower-case letters, digits "
                          "and _, starting with a letter, at most 32)")
    path = Path(config_path or default_config_path(world))
    if not path.is_file():
        raise ConfigError(f"world: unknown world {world!r}; choose one of "
                          f"{simulated_world_names()}, or describe a recorded world in "
                          f"{path} (kind: {RECORDED_KIND})")
    try:
        kind = (yaml.safe_load(path.read_text()) or {}).get("kind")
    except (yaml.YAMLError, AttributeError):
        kind = None
    if kind != RECORDED_KIND:
        raise ConfigError(f"world: {world!r} is not a simulated world (those are "
                          f"{simulated_world_names()}, registered in SIMULATED_WORLDS of "
                          f"app/worlds/registry.py), so {path} must be `kind: {RECORDED_KIND}`")
    return True


def simulated_world_names() -> str:
    """The registered simulated worlds, for help texts and errors ("highway, obstacle")."""
    return ", ".join(SIMULATED_WORLDS)


def build_world(world: str, config_path: Path | None = None, policy: str = "mpc") -> World:
    """Load the world's typed config and construct it; errors name the field (which policies a
    simulated world rolls out is its builder's to say)."""
    path = config_path or default_config_path(world)
    if is_recorded(world, path):
        if policy != "mpc":
            raise ConfigError(f"policy: a recorded world's moves are recorded; {world} takes "
                              "no policy")
        from app.worlds.recorded import RecordedWorld

        return RecordedWorld.from_yaml(world, path)
    return SIMULATED_WORLDS[world](path, policy)


def require_mpc(world: str, policy: str) -> None:
    """ConfigError unless `policy` is the sampling MPC, the only policy most worlds have."""
    if policy != "mpc":
        raise ConfigError(f"policy: {world} supports only 'mpc'")


def build_highway_world(path: Path, policy: str) -> World:
    """The Highway world: both cars on the sampling MPC."""
    require_mpc("highway", policy)
    from app.worlds.highway import HighwayWorld

    return HighwayWorld.from_yaml(path)


def build_obstacle_world(path: Path, policy: str) -> World:
    """The Obstacle world, its agents on the MPC or on the SAC policy passed into it."""
    from app.worlds.obstacle import ObstacleConfig, ObstacleWorld

    if policy not in ("mpc", "sac"):
        raise ConfigError(f"policy: unknown policy {policy!r} for obstacle; choose mpc or sac")
    config = load_yaml_model(path, ObstacleConfig)
    if policy == "mpc":
        return ObstacleWorld(config)
    from app.worlds.sac import SACPolicy

    return ObstacleWorld(config, agent_policy=SACPolicy(config))


# Every simulated world: its name (the CLI's and study configs' `world`, the folder under the
# data dir) -> the function that builds it from its YAML path and policy. A builder imports its
# world's module itself, so only the world in use loads (highway-env, torch for SAC).
SIMULATED_WORLDS: dict[str, Callable[[Path, str], World]] = {
    "highway": build_highway_world,
    "obstacle": build_obstacle_world,
}
