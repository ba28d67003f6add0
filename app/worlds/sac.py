"""Soft actor-critic for the Obstacle world, trained once and rolled out for both agents.

One goal-conditioned policy is learnt on the world's own reward (`ObstacleWorld.reward`) in a
gymnasium env where the learner is one agent and the other agent is driven by the world's MPC.
The trained policy is saved under <data dir>/policies/obstacle_sac.zip with a meta.json that
names the exact world config it was trained on, so a changed config retrains instead of
silently reusing a stale policy. `SACPolicy` is what an `ObstacleWorld` is given to act with
(see `registry.build_world`); this module depends on the world, never the other way round.
"""

import json
import time
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from tqdm import tqdm

from app.core.files import atomic_path, sha256_bytes, write_json
from app.data.trajectory import HUMAN, ROBOT, Rejected
from app.layout import Layout
from app.settings import get_settings
from app.worlds.obstacle import ObstacleConfig, ObstacleWorld

POLICY_NAME = "obstacle_sac"
LEARNER, OTHER = ROBOT, HUMAN
# prepare() runs in the parent before the simulation pool forks; workers inherit this map and
# load the same file even when the data dir was passed as an argument rather than settings.
_PREPARED: dict[str, Path] = {}


class ObstacleAgentEnv(gym.Env):
    """One goal-conditioned agent (the learner) next to an MPC-driven other agent."""

    metadata = {"render_modes": []}

    def __init__(self, world: ObstacleWorld):
        self.world = world
        self.vmax = world.config.max_speed_mps
        dim = len(world.observation(np.zeros(2), 0, np.zeros(2), np.zeros(2)))
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (dim,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def _observe(self) -> np.ndarray:
        return self.world.observation(self.pos[LEARNER], self.goals[LEARNER], self.pos[OTHER],
                                      self.vel[OTHER])

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """New random goals and starts (the world's own task distribution)."""
        super().reset(seed=seed)
        while True:
            try:
                self.goals, self.pos = self.world.sample_task(self.np_random)
                break
            except Rejected:
                continue
        self.vel = np.zeros((2, 2))
        self.other_arrived = False
        self.other_plan = self.world.initial_plan(self.pos[OTHER], self.vel[OTHER],
                                                  self.goals[OTHER])
        self.t = 0
        return self._observe(), {}

    def step(self, action: np.ndarray):
        """Move both agents one dt; reward is the learner's world reward."""
        world = self.world
        new_vel = np.zeros((2, 2))
        new_vel[LEARNER] = world.limit_speed(np.asarray(action, np.float64) * self.vmax)
        if not self.other_arrived:
            new_vel[OTHER], self.other_plan = world.mpc_action(
                OTHER, self.pos, self.vel, self.goals, self.other_plan, self.np_random)
        new_pos = self.pos + new_vel * world.dt_s
        arrived = bool(world.in_goal(self.goals[LEARNER], new_pos[LEARNER]))
        reward = float(world.reward(self.goals[LEARNER], self.pos[LEARNER], new_pos[LEARNER],
                                    new_pos[OTHER], new_vel[LEARNER], self.vel[LEARNER],
                                    np.array(arrived)))
        crashed = False
        try:
            world.check_safety(self.pos, new_pos)
        except Rejected:
            crashed = True
            reward -= world.config.reward.collision_penalty
        self.pos, self.vel, self.t = new_pos, new_vel, self.t + 1
        self.other_arrived |= bool(world.in_goal(self.goals[OTHER], new_pos[OTHER]))
        truncated = self.t >= world.config.max_steps
        return self._observe(), reward, arrived or crashed, truncated, {"crashed": crashed}


class SACPolicy:
    """The SAC policy of one obstacle config, used deterministically: observation -> action
    in [-1, 1]^2. An `ObstacleWorld`'s `AgentPolicy`."""

    def __init__(self, config: ObstacleConfig, model: SAC | None = None):
        self.config = config
        self.model = model  # None: loaded on first use from where `prepare` left it

    def prepare(self, layout: Layout) -> None:
        """Load the policy trained on this config, or train, evaluate and save it first."""
        self.model = prepare_model(self.config, layout)

    def act(self, observation: np.ndarray) -> np.ndarray:
        """Deterministic (mean) action for one observation."""
        if self.model is None:
            self.model = load_prepared_model(self.config)
        action, _ = self.model.predict(observation, deterministic=True)
        return np.asarray(action, dtype=np.float64)


def config_key(config: ObstacleConfig) -> str:
    """SHA-256 of the world config the policy depends on (all of it: reward, geometry, SAC)."""
    text = json.dumps(config.model_dump(), sort_keys=True)
    return sha256_bytes(text.encode())


def prepare_model(config: ObstacleConfig, layout: Layout) -> SAC:
    """Load the model trained on this exact config, or train, evaluate and save it."""
    zip_path, meta_path = layout.policy(POLICY_NAME), layout.policy_meta(POLICY_NAME)
    key = config_key(config)
    if not _is_current(zip_path, meta_path, key):
        model, train_s = train_sac_policy(config)
        with atomic_path(zip_path) as tmp, open(tmp, "wb") as fh:
            model.save(fh)
        evaluation = evaluate_policy(SACPolicy(config, model), config.sac.eval_episodes)
        write_json(meta_path, {"config_sha256": key, "config": config.model_dump(),
                               "total_timesteps": config.sac.total_timesteps,
                               "train_wall_time_s": round(train_s, 2),
                               "evaluation": evaluation, "file": zip_path.name})
    _PREPARED[key] = zip_path
    return load_sac_model(zip_path)


def _is_current(zip_path: Path, meta_path: Path, key: str) -> bool:
    """A saved policy exists and its meta.json names this config."""
    if not (zip_path.exists() and meta_path.exists()):
        return False
    return json.loads(meta_path.read_text()).get("config_sha256") == key


def load_sac_model(zip_path: Path) -> SAC:
    """Load a saved SAC model on the CPU."""
    return SAC.load(zip_path, device="cpu")


def load_prepared_model(config: ObstacleConfig) -> SAC:
    """The model `prepare_model` made for this config (in this process or its parent)."""
    key = config_key(config)
    zip_path = _PREPARED.get(key)
    if zip_path is None:
        layout = get_settings().layout
        zip_path, meta_path = layout.policy(POLICY_NAME), layout.policy_meta(POLICY_NAME)
        if not _is_current(zip_path, meta_path, key):
            raise RuntimeError(f"no SAC policy trained on this obstacle config at {zip_path}; "
                               "call ObstacleWorld.prepare(layout) first")
    return load_sac_model(zip_path)


def train_sac_policy(config: ObstacleConfig) -> tuple[SAC, float]:
    """Train SB3 SAC on ObstacleAgentEnv of an MPC-driven world; returns (model, wall time [s])."""
    cfg = config.sac
    torch.set_num_threads(cfg.torch_threads)
    env = ObstacleAgentEnv(ObstacleWorld(config))
    env.reset(seed=cfg.seed)
    model = SAC("MlpPolicy", env, learning_rate=cfg.learning_rate, buffer_size=cfg.buffer_size,
                learning_starts=cfg.learning_starts, batch_size=cfg.batch_size, gamma=cfg.gamma,
                policy_kwargs={"net_arch": list(cfg.hidden_units)}, seed=cfg.seed,
                device="cpu", verbose=0)
    started = time.perf_counter()
    model.learn(total_timesteps=cfg.total_timesteps, callback=TqdmCallback(cfg.total_timesteps))
    return model, time.perf_counter() - started


class TqdmCallback(BaseCallback):
    """Progress bar over environment steps."""

    def __init__(self, total: int):
        super().__init__()
        self.total = total

    def _on_training_start(self) -> None:
        self.bar = tqdm(total=self.total, desc="train obstacle SAC", unit="step")

    def _on_step(self) -> bool:
        self.bar.update(1)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def evaluate_policy(policy: SACPolicy, n_episodes: int, seed: int = 12345) -> dict:
    """Both agents on the SAC policy: kept (goal reached, no collision) and rejection rates."""
    sac_world = ObstacleWorld(policy.config, agent_policy=policy)
    outcomes: Counter = Counter()
    for i in range(n_episodes):
        try:
            episode = sac_world.rollout(np.random.default_rng([seed, i]))
            outcomes["kept"] += 1
            outcomes["human_reached"] += episode.labels["human_reached_goal"]
        except Rejected as why:
            outcomes[str(why)] += 1
    return {"episodes": n_episodes,
            "kept_rate": outcomes["kept"] / n_episodes,  # robot reached its goal, no collision
            "human_goal_reach_rate_in_kept": outcomes["human_reached"] / max(1, outcomes["kept"]),
            "rejections": {k: v for k, v in sorted(outcomes.items())
                           if k not in ("kept", "human_reached")}}
