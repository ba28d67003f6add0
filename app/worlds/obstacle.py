"""Obstacle world: a robot and a human disc each drive to one of four goals around obstacles.

Shape legend: A = 2 agents (0 robot, 1 human), D = 2 (x, y), K MPC candidates, H horizon steps.
Coordinates are metres in the scene frame: origin at the top-left corner, y grows downwards.
Both agents optimise the same kind of reward (progress along a geodesic distance-to-goal field,
clearance from obstacles, walls and the other agent predicted at constant velocity, effort),
with the shared sampling MPC by default, or with a learnt `AgentPolicy` passed in (the soft
actor-critic of sac.py, which `registry.build_world(..., policy="sac")` wires up).
"""

from pathlib import Path
from typing import Protocol

import numpy as np
from pydantic import Field, model_validator

from app.configio import StrictModel, load_yaml_model
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR, AgentShape, Bounds, Circle, Scene
from app.data.trajectory import HUMAN, ROBOT, Covered, Episode, Rejected
from app.layout import Layout
from app.worlds.geodesic import GeodesicFields
from app.worlds.mpc import SamplingMPC

AGENTS = (ROBOT, HUMAN)
COLLISION_SUBSTEPS = 4  # check each step's straight segment at 4 points, not just its end


class GoalConfig(StrictModel):
    """A goal's centre [m] and name."""

    # the goal centre's x (m from the scene's left edge)
    x_m: float
    # the goal centre's y (m from the top edge; y grows downwards)
    y_m: float
    # the goal's name, carried in the scene the pages draw
    label: str


class ObstacleCircle(StrictModel):
    """A static circular obstacle [m]."""

    # the obstacle centre's x (m from the left edge)
    x_m: float
    # the obstacle centre's y (m from the top edge)
    y_m: float
    # the obstacle's radius (m, > 0); the agents' discs may not touch it
    radius_m: float = Field(gt=0)


class StartConfig(StrictModel):
    """How random start positions are drawn (rejection sampling)."""

    # shortest path-around-obstacles distance (m, > 0) from a start to its agent's goal
    min_goal_distance_m: float = Field(gt=0)
    # longest such distance (m, >= min_goal_distance_m): longer starts give longer episodes
    max_goal_distance_m: float = Field(gt=0)
    # smallest distance (m, >= 0) between the two agents' start centres
    min_separation_m: float = Field(ge=0)
    # free space (m, >= 0) a start keeps between the agent's disc and every obstacle and wall
    obstacle_margin_m: float = Field(ge=0)
    # free space (m, >= 0) a start keeps between the agent's disc and every goal circle
    goal_margin_m: float = Field(ge=0)


class RewardConfig(StrictModel):
    """Weights of the per-step reward both agents optimise."""

    # weight (>= 0) of progress along the distance-to-goal field, scaled so a full-speed step
    # downhill counts 1
    progress_weight: float = Field(ge=0)
    # clearance (m, >= 0) from obstacles and walls below which the squared shortfall is penalised
    obstacle_clearance_m: float = Field(ge=0)
    # weight (>= 0) of the squared obstacle clearance shortfall, per m^2
    obstacle_weight: float = Field(ge=0)
    # clearance (m, >= 0) from the other agent's disc below which the squared shortfall is penalised
    agent_clearance_m: float = Field(ge=0)
    # weight (>= 0) of the squared agent clearance shortfall, per m^2
    agent_weight: float = Field(ge=0)
    # weight (>= 0) of the squared wall clearance shortfall (against obstacle_clearance_m), per m^2
    bounds_weight: float = Field(ge=0)
    # penalty (>= 0) for each obstacle, agent or wall the disc overlaps at a step
    collision_penalty: float = Field(ge=0)
    # weight (>= 0) of (speed / max_speed_mps)^2: effort
    effort_weight: float = Field(ge=0)
    # weight (>= 0) of (change of velocity / max_speed_mps)^2 between steps: smoothness
    smoothness_weight: float = Field(ge=0)
    # reward (>= 0) at the step an agent first enters its goal
    goal_bonus: float = Field(ge=0)
    # per-step discount (0-1] of the MPC's reward over its horizon
    discount: float = Field(gt=0, le=1)


class GeodesicConfig(StrictModel):
    """Grid on which the distance-to-goal fields around the obstacles are computed."""

    # grid spacing (m, 0-1] of the distance-to-goal fields; finer grids follow the obstacles more
    # closely and take longer to build
    grid_step_m: float = Field(gt=0, le=1)
    # extra margin (m, >= 0) each obstacle is grown by, beyond the agent's radius, when the fields
    # are computed
    inflation_m: float = Field(ge=0)
    # how many times (>= 1) longer an edge touching a blocked grid node is: how strongly paths avoid
    # the grown obstacles
    blocked_cost_factor: float = Field(ge=1)


class MPCConfig(StrictModel):
    """Sampling MPC size."""

    # steps (>= 1) each agent's sampling MPC plans ahead (the other agent predicted at constant
    # velocity)
    horizon_steps: int = Field(ge=1)
    # candidate velocity sequences (>= 4) drawn per MPC iteration
    n_samples: int = Field(ge=4)
    # cross-entropy refinements (>= 1) of the sampling distribution per step
    iterations: int = Field(ge=1)


class SACConfig(StrictModel):
    """Soft actor-critic training of the goal-conditioned agent policy."""

    # environment steps (>= 1) of SAC training; read only when the world is built with policy sac
    total_timesteps: int = Field(ge=1)
    # the SAC optimiser's learning rate (> 0)
    learning_rate: float = Field(gt=0)
    # width of each hidden layer of the actor and critic networks (one entry per layer)
    hidden_units: list[int] = Field(min_length=1)
    # transitions (>= 1) per gradient step
    batch_size: int = Field(ge=1)
    # transitions (>= 1) the replay buffer holds
    buffer_size: int = Field(ge=1)
    # environment steps (>= 0) collected before training begins
    learning_starts: int = Field(ge=0)
    # the discount (0-1] of SAC's return
    gamma: float = Field(gt=0, le=1)
    # CPU threads (1-2) torch uses while training
    torch_threads: int = Field(ge=1, le=2)
    # episodes (>= 1) run after training to report the kept and rejection rates in the policy's
    # meta.json
    eval_episodes: int = Field(ge=1)
    # seed (>= 0) of the SAC training and its environment
    seed: int = Field(ge=0)


class ObstacleConfig(StrictModel):
    """Everything that defines the Obstacle world."""

    # seconds (> 0) per step: the time step of the stored trajectories and of a participant's clicks
    dt_s: float = Field(gt=0)
    # steps (>= 1) a rollout may take; one where the robot has not reached its goal by then is
    # rejected
    max_steps: int = Field(ge=1)
    # the scene's width (m, > 0)
    width_m: float = Field(gt=0)
    # the scene's height (m, > 0)
    height_m: float = Field(gt=0)
    # each agent's disc radius (m, > 0), for collisions, clearances and drawing
    agent_radius_m: float = Field(gt=0)
    # the fastest an agent may move (m/s, > 0); faster commands are scaled down
    max_speed_mps: float = Field(gt=0)
    # radius (m, > 0) of a goal circle: an agent whose centre is inside it has arrived and stops
    goal_radius_m: float = Field(gt=0)
    # the goals (at least 2); each episode gives the two agents distinct goals at random
    goals: list[GoalConfig] = Field(min_length=2)
    # the static circular obstacles
    obstacles: list[ObstacleCircle]
    # how start positions are drawn
    start: StartConfig
    # the per-step reward both agents maximise
    reward: RewardConfig
    # the grid of the distance-to-goal fields the reward's progress is measured on
    geodesic: GeodesicConfig
    # the sampling MPC's sizes (the default policy)
    mpc: MPCConfig
    # the soft actor-critic training, used only when the world is built with policy sac
    sac: SACConfig

    @model_validator(mode="after")
    def _distances_ordered(self) -> "ObstacleConfig":
        if self.start.min_goal_distance_m > self.start.max_goal_distance_m:
            raise ValueError("start.min_goal_distance_m must not exceed start.max_goal_distance_m")
        return self


def world_fields(config: ObstacleConfig) -> GeodesicFields:
    """The policy's distance-to-goal fields: obstacles grown by the agent and the inflation."""
    grown = config.agent_radius_m, config.geodesic.inflation_m
    return GeodesicFields(
        (config.width_m, config.height_m),
        [(o.x_m, o.y_m, o.radius_m + grown[0] + grown[1]) for o in config.obstacles],
        [(g.x_m, g.y_m) for g in config.goals],
        config.geodesic.grid_step_m, config.geodesic.blocked_cost_factor)


class AgentPolicy(Protocol):
    """A learnt policy that moves both agents instead of the MPC (sac.py's `SACPolicy`)."""

    def prepare(self, layout: Layout) -> None:
        """Train or load it once, in the parent before simulation workers fork."""
        ...

    def act(self, observation: np.ndarray) -> np.ndarray:
        """The action in [-1, 1]^2 (a velocity over the speed limit) for one observation."""
        ...


class ObstacleWorld:
    """The Obstacle world: random distinct goals and starts, both agents reward-optimising."""

    name = "obstacle"
    robot_label = "robot_goal"
    starts_as_recorded = False

    def __init__(self, config: ObstacleConfig, agent_policy: AgentPolicy | None = None):
        self.config = config
        self.agent_policy = agent_policy  # None: both agents run the sampling MPC
        self.dt_s = config.dt_s
        self.fields = world_fields(config)
        goal_names = [goal.label for goal in config.goals]
        self.label_names = {
            "robot_goal": goal_names,
            "human_goal": goal_names,
            "robot_reached_goal": ["no", "yes"],
            "human_reached_goal": ["no", "yes"],
        }
        self._goal_xy = np.array([[g.x_m, g.y_m] for g in config.goals])
        self._obs_xy = np.array([[o.x_m, o.y_m] for o in config.obstacles]).reshape(-1, 2)
        self._obs_r = np.array([o.radius_m for o in config.obstacles])
        vmax = config.max_speed_mps
        self.mpc = SamplingMPC(horizon=config.mpc.horizon_steps, n_samples=config.mpc.n_samples,
                               control_low=(-vmax, -vmax), control_high=(vmax, vmax),
                               iterations=config.mpc.iterations)
        self._discounts = config.reward.discount ** np.arange(config.mpc.horizon_steps)

    @classmethod
    def from_yaml(cls, path: Path) -> "ObstacleWorld":
        """Load study_configs/worlds/obstacle.yaml (or another file) into an MPC-driven world."""
        return cls(load_yaml_model(path, ObstacleConfig))

    # ----- geometry ---------------------------------------------------------------------------

    def scene(self) -> Scene:
        """Bounds, obstacles and goals for plots and the browser."""
        c = self.config
        r = c.agent_radius_m
        return Scene(
            world=self.name, dt_s=c.dt_s,
            frame="metres from the top-left corner of the plane, y grows downwards",
            bounds=Bounds(x_min_m=0.0, x_max_m=c.width_m, y_min_m=0.0, y_max_m=c.height_m),
            obstacles=[Circle(x_m=o.x_m, y_m=o.y_m, radius_m=o.radius_m) for o in c.obstacles],
            goals=[Circle(x_m=g.x_m, y_m=g.y_m, radius_m=c.goal_radius_m, label=g.label)
                   for g in c.goals],
            agents=[AgentShape(name="robot", kind="disc", length_m=2 * r, width_m=2 * r,
                               color=ROBOT_COLOR),
                    AgentShape(name="human", kind="disc", length_m=2 * r, width_m=2 * r,
                               color=HUMAN_COLOR)],
        )

    def limit_speed(self, velocity: np.ndarray) -> np.ndarray:
        """Scale velocities [..., 2] down to the speed limit, keeping their direction."""
        speed = norm2(velocity)[..., None]
        return velocity * np.minimum(1.0, self.config.max_speed_mps / np.maximum(speed, 1e-12))

    def in_goal(self, goal: int | np.ndarray, points: np.ndarray) -> np.ndarray:
        """Whether points [..., 2] lie inside goal region(s) `goal`."""
        return norm2(points - self._goal_xy[goal]) <= self.config.goal_radius_m

    def obstacle_gap(self, points: np.ndarray) -> np.ndarray:
        """Smallest distance [m] between an agent disc at points [..., 2] and any obstacle."""
        if len(self._obs_r) == 0:
            return np.full(points.shape[:-1], np.inf)
        dx = points[..., 0, None] - self._obs_xy[:, 0]
        dy = points[..., 1, None] - self._obs_xy[:, 1]
        centre = np.sqrt(dx * dx + dy * dy)
        return (centre - self._obs_r - self.config.agent_radius_m).min(axis=-1)

    def wall_gap(self, points: np.ndarray) -> np.ndarray:
        """Smallest distance [m] between an agent disc at points [..., 2] and the walls."""
        c, r = self.config, self.config.agent_radius_m
        x, y = points[..., 0], points[..., 1]
        return np.minimum(np.minimum(x, c.width_m - x), np.minimum(y, c.height_m - y)) - r

    def agent_gap(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Distance [m] between the two agent discs at a, b [..., 2]."""
        return norm2(a - b) - 2 * self.config.agent_radius_m

    # ----- reward -----------------------------------------------------------------------------

    def reward(self, goal: int, prev: np.ndarray, pos: np.ndarray, other: np.ndarray,
               velocity: np.ndarray, prev_velocity: np.ndarray,
               arrived_now: np.ndarray) -> np.ndarray:
        """Per-step reward [...] of moving prev -> pos [..., 2] at `velocity`, other at `other`."""
        progress_m = self.fields.distance(goal, prev) - self.fields.distance(goal, pos)
        return self._reward(progress_m, pos, other, velocity, prev_velocity, arrived_now)

    def _reward(self, progress_m, pos, other, velocity, prev_velocity, arrived_now):
        w = self.config.reward
        vmax = self.config.max_speed_mps
        progress = progress_m / (vmax * self.dt_s)  # 1 per step at full speed downhill
        penalty = self._clearance_penalty(pos, other)
        effort = norm2(velocity) ** 2 / vmax**2
        jerk = norm2(velocity - prev_velocity) ** 2 / vmax**2
        return (w.progress_weight * progress - penalty - w.effort_weight * effort
                - w.smoothness_weight * jerk + w.goal_bonus * arrived_now)

    def _clearance_penalty(self, pos: np.ndarray, other: np.ndarray) -> np.ndarray:
        w = self.config.reward
        penalty = np.zeros(pos.shape[:-1])
        for gap, clearance, weight in (
            (self.obstacle_gap(pos), w.obstacle_clearance_m, w.obstacle_weight),
            (self.agent_gap(pos, other), w.agent_clearance_m, w.agent_weight),
            (self.wall_gap(pos), w.obstacle_clearance_m, w.bounds_weight),
        ):
            penalty += weight * np.maximum(clearance - gap, 0.0) ** 2
            penalty += w.collision_penalty * (gap < 0)
        return penalty

    def mpc_cost(self, agent_pos: np.ndarray, agent_velocity: np.ndarray, goal: int,
                 other_pos: np.ndarray, other_velocity: np.ndarray):
        """Cost of controls [K, H, 2] for one agent; the other moves at constant velocity."""
        dt, horizon = self.dt_s, self.config.mpc.horizon_steps
        steps = np.arange(1, horizon + 1)[:, None]
        other_path = other_pos + other_velocity * dt * steps  # [H, 2]
        start_to_go = self.fields.distance(goal, agent_pos)

        def cost(controls: np.ndarray) -> np.ndarray:
            velocity = self.limit_speed(controls)
            path = agent_pos + np.cumsum(velocity * dt, axis=1)
            inside = self.in_goal(goal, path)
            arrived = np.logical_or.accumulate(inside, axis=1)
            arrived_before = np.zeros_like(arrived)
            arrived_before[:, 1:] = arrived[:, :-1]
            if arrived_before.any():  # an agent stops once it is inside its goal
                velocity = np.where(arrived_before[..., None], 0.0, velocity)
                path = agent_pos + np.cumsum(velocity * dt, axis=1)
            to_go = self.fields.distance(goal, path)
            progress_m = -np.diff(to_go, axis=1, prepend=start_to_go)
            prev_velocity = np.concatenate(
                [np.broadcast_to(agent_velocity, (len(path), 1, 2)), velocity[:, :-1]], axis=1)
            arrived_now = arrived & ~arrived_before
            rewards = self._reward(progress_m, path, other_path, velocity, prev_velocity,
                                   arrived_now)
            return -(rewards * self._discounts).sum(axis=1)

        return cost

    # ----- tasks and rollouts -----------------------------------------------------------------

    def sample_task(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Distinct random goals [2] and collision-free start positions [2, 2]."""
        goals = rng.choice(len(self.config.goals), size=2, replace=False)
        starts = np.zeros((2, 2))
        for agent in AGENTS:
            starts[agent] = self._sample_start(goals[agent], starts[:agent], rng)
        return goals, starts

    def _sample_start(self, goal: int, taken: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        c, s = self.config, self.config.start
        low = np.array([c.agent_radius_m + s.obstacle_margin_m] * 2)
        high = np.array([c.width_m, c.height_m]) - low
        for _ in range(1000):
            candidates = rng.uniform(low, high, size=(64, 2))
            ok = self.obstacle_gap(candidates) > s.obstacle_margin_m
            goal_dist = np.linalg.norm(candidates[:, None] - self._goal_xy, axis=-1)
            ok &= (goal_dist > c.goal_radius_m + c.agent_radius_m + s.goal_margin_m).all(axis=1)
            geo = self.fields.distance(goal, candidates)
            ok &= (geo >= s.min_goal_distance_m) & (geo <= s.max_goal_distance_m)
            for other in taken:
                ok &= np.linalg.norm(candidates - other, axis=-1) >= s.min_separation_m
            if ok.any():
                return candidates[np.argmax(ok)]
        raise Rejected("no valid start position")

    def rollout(self, rng: np.random.Generator) -> Episode:
        """One interaction; raises Rejected on a collision or when the robot misses its goal."""
        goals, starts = self.sample_task(rng)
        positions, arrival = self._simulate(starts, np.zeros((2, 2)), goals, rng,
                                            self.config.max_steps, check_safety=True)
        if arrival[ROBOT] < 0:
            raise Rejected("robot did not reach its goal")
        headings, speeds = headings_and_speeds(positions, self.dt_s)
        labels = {
            "robot_goal": int(goals[ROBOT]),
            "human_goal": int(goals[HUMAN]),
            "robot_reached_goal": int(arrival[ROBOT] >= 0),
            "human_reached_goal": int(arrival[HUMAN] >= 0),
            "robot_arrival_step": int(arrival[ROBOT]),
        }
        return Episode(positions=positions, headings=headings, speeds=speeds, labels=labels)

    def _simulate(self, starts: np.ndarray, velocities: np.ndarray, goals: np.ndarray,
                  rng: np.random.Generator, n_steps: int, check_safety: bool,
                  human_constant: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Step both agents; returns positions [L+1, 2, 2] and first arrival steps [2] (-1)."""
        pos, vel = starts.astype(np.float64).copy(), velocities.astype(np.float64).copy()
        arrival = np.where(self.in_goal(goals, pos), 0, -1)
        plans = [self.initial_plan(pos[a], vel[a], goals[a]) for a in AGENTS]
        track = [pos.copy()]
        for t in range(1, n_steps + 1):
            new_vel = np.zeros((2, 2))
            for a in AGENTS:
                if a == HUMAN and human_constant:
                    new_vel[a] = vel[a]
                    continue
                if arrival[a] >= 0:
                    continue
                new_vel[a], plans[a] = self._act(a, pos, vel, goals, plans[a], rng)
            new_pos = pos + new_vel * self.dt_s
            if check_safety:
                self.check_safety(pos, new_pos)
            pos, vel = new_pos, new_vel
            track.append(pos.copy())
            arrival = np.where((arrival < 0) & self.in_goal(goals, pos), t, arrival)
            if (arrival >= 0).all() and not human_constant:
                break
        return np.stack(track), arrival

    def initial_plan(self, pos: np.ndarray, vel: np.ndarray, goal: int) -> np.ndarray:
        """Warm start: keep the current velocity, or head downhill at full speed from rest."""
        if np.linalg.norm(vel) < 1e-6:
            vel = self.fields.downhill(goal, pos) * self.config.max_speed_mps
        return np.broadcast_to(vel, (self.config.mpc.horizon_steps, 2)).copy()

    def _act(self, agent: int, pos: np.ndarray, vel: np.ndarray, goals: np.ndarray,
             plan: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The agent's next velocity [2] and the warm start for its next plan."""
        other = 1 - agent
        if self.agent_policy is not None:
            obs = self.observation(pos[agent], goals[agent], pos[other], vel[other])
            action = self.agent_policy.act(obs)
            return self.limit_speed(action * self.config.max_speed_mps), plan
        return self.mpc_action(agent, pos, vel, goals, plan, rng)

    def mpc_action(self, agent: int, pos: np.ndarray, vel: np.ndarray, goals: np.ndarray,
                   plan: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The MPC's next velocity [2] for `agent` and the warm start for its next plan."""
        other = 1 - agent
        cost = self.mpc_cost(pos[agent], vel[agent], goals[agent], pos[other], vel[other])
        best = self.mpc.plan(cost, plan, rng)
        return self.limit_speed(best[0]), self.mpc.shift(best)

    def check_safety(self, pos: np.ndarray, new_pos: np.ndarray) -> None:
        """Raise Rejected if the straight moves pos -> new_pos [2, 2] hit anything."""
        fractions = np.arange(1, COLLISION_SUBSTEPS + 1)[:, None, None] / COLLISION_SUBSTEPS
        points = pos + (new_pos - pos) * fractions  # [S, 2 agents, 2]
        if (self.obstacle_gap(points) < 0).any():
            raise Rejected("collision with an obstacle")
        if (self.agent_gap(points[:, ROBOT], points[:, HUMAN]) < 0).any():
            raise Rejected("agents collided")
        if (self.wall_gap(points) < 0).any():
            raise Rejected("out of bounds")

    def robot_policy_actions(self, positions: np.ndarray, robot_heading: float,
                             robot_speed: float, human_velocity: np.ndarray, labels: dict,
                             n_steps: int, rng: np.random.Generator) -> np.ndarray:
        """The robot's own policy [n_steps, 2] from any state, the human at constant velocity."""
        goals = np.array([int(labels["robot_goal"]), int(labels.get("human_goal", 0))])
        velocities = np.zeros((2, 2))
        velocities[ROBOT] = robot_speed * np.array([np.cos(robot_heading), np.sin(robot_heading)])
        velocities[HUMAN] = np.asarray(human_velocity, dtype=np.float64)
        track, _ = self._simulate(np.asarray(positions, dtype=np.float64), velocities, goals, rng,
                                  n_steps, check_safety=False, human_constant=True)
        actions = np.diff(track[:, ROBOT], axis=0) / self.dt_s
        return np.concatenate([actions, np.zeros((n_steps - len(actions), 2))])

    # ----- a learnt agent policy --------------------------------------------------------------

    def observation(self, pos: np.ndarray, goal: int, other_pos: np.ndarray,
                    other_vel: np.ndarray) -> np.ndarray:
        """One agent's observation, float32, scaled to about [-1, 1]: own position, goal one-hot,
        the geodesic field's downhill direction and distance to go at the own position (map
        knowledge that makes a few tens of thousands of SAC steps enough), the other agent's
        relative position and velocity."""
        c = self.config
        half = np.array([c.width_m, c.height_m]) / 2
        one_hot = np.eye(len(c.goals))[goal]
        geo = self.fields.distance(goal, pos) / (c.width_m + c.height_m)
        return np.concatenate([
            (pos - half) / half, one_hot, self.fields.downhill(goal, pos), [geo],
            (other_pos - pos) / half, other_vel / c.max_speed_mps,
        ]).astype(np.float32)

    def prepare(self, layout: Layout) -> None:
        """Train or load the agent policy, if any, once (in the parent, before workers fork)."""
        if self.agent_policy is not None:
            self.agent_policy.prepare(layout)

    # ----- segments and start states for the trial bank ---------------------------------------

    def visible_ends(self, robot_track: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Well before the goal: at least 40% of the start-to-goal distance still to go."""
        remaining = np.linalg.norm(robot_track[ends] - robot_track[-1], axis=1)
        return ends[remaining >= 0.4 * np.linalg.norm(robot_track[0] - robot_track[-1])]

    def data_start_candidates(self, scene: Scene, segment: np.ndarray, covered: Covered,
                              reach: float) -> dict[str, np.ndarray]:
        """`near` (within `reach` of the robot) and `mid` (`reach` to 2 `reach`) states
        (indices into `covered`), more than one agent width clear of every obstacle and goal
        disc and two from the human (the whole walled plane is in view, so there is always
        room for n steps)."""
        robot, human = segment[-1, ROBOT], segment[-1, HUMAN]
        dist = np.linalg.norm(covered.positions - robot, axis=1)
        index = np.flatnonzero(dist <= 2 * reach)
        pts, dist = covered.positions[index], dist[index]
        agent = max(a.width_m for a in scene.agents)
        clear = np.linalg.norm(pts - human, axis=1) > 2 * agent
        for c in [*scene.obstacles, *scene.goals]:
            clear &= np.hypot(pts[:, 0] - c.x_m, pts[:, 1] - c.y_m) > c.radius_m + agent
        return {"near": index[clear & (dist <= reach)], "mid": index[clear & (dist > reach)]}


def norm2(vectors: np.ndarray) -> np.ndarray:
    """Euclidean length of 2-D vectors [..., 2] (faster than np.linalg.norm for small D)."""
    return np.sqrt(vectors[..., 0] ** 2 + vectors[..., 1] ** 2)


def headings_and_speeds(positions: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Heading [rad] and speed [m/s] of each agent at each state, from its motion into it."""
    steps = np.diff(positions, axis=0)  # [L, A, D]
    lengths = np.linalg.norm(steps, axis=-1)  # [L, A]
    speeds = np.concatenate([np.zeros((1, positions.shape[1])), lengths / dt_s])
    if len(steps) == 0:
        return np.zeros(positions.shape[:2]), speeds
    angles = np.arctan2(steps[..., 1], steps[..., 0])
    moving = lengths > 1e-9
    first = moving.argmax(axis=0)  # first moving step (0 if it never moves)
    latest = np.maximum.accumulate(np.where(moving, np.arange(len(steps))[:, None], -1), axis=0)
    source = np.where(latest >= 0, latest, first)  # a stopped agent keeps its last heading
    agents = np.arange(positions.shape[1])
    return np.concatenate([angles[first, agents][None], angles[source, agents]]), speeds
