"""Highway world: two cars on highway-env's straight road, each driven by its own sampling MPC.

Agent 0 is the robot, agent 1 the human; there is no other traffic. highway-env supplies the
road (`RoadNetwork.straight_road_network`, 4 m lanes, lane 0 on top, y grows downwards), the
vehicle kinematics (`Vehicle.act` / `Vehicle.step`, a kinematic bicycle) and the collision
check (`Road.step` -> `handle_collisions`). Rewards, crash and off-road checks are per agent
and written here, because highway-v0 only scores its first vehicle.

Frame of the stored positions: x is measured along the road relative to a point that moves
forward at the constant `frame_speed_mps`, slower than every car (19 m/s against cars at
22.5-25.5 m/s), and that starts `frame_start_x_m` behind the cars' initial midpoint; y is
highway-env's lateral coordinate. So every car drives forward on screen (rollouts where a
car's on-screen speed drops below `min_display_speed_mps` are rejected as `slow_on_screen`),
keeping the lane is a forward move and merging a forward-sideways one, and positions stay
in a view of fixed size. The browser scrolls the lane markings backwards at the frame's
speed, so the clip reads as traffic driving forward on a road seen from a slower camera.

Shape legend inside the MPC cost: K candidates, H horizon steps, U = 2 controls
(acceleration [m/s^2], steering [rad]).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.utils import wrap_to_pi
from highway_env.vehicle.kinematics import Vehicle
from pydantic import Field, model_validator

from app.configio import StrictModel, load_yaml_model
from app.data.scene import HUMAN_COLOR, ROBOT_COLOR, AgentShape, Bounds, Lane, Scene
from app.data.trajectory import HUMAN, ROBOT, Covered, Episode, Rejected
from app.layout import Layout
from app.worlds.mpc import SamplingMPC

INTENTS = ["keep", "left", "right"]
LANE_SHIFT = {0: 0, 1: -1, 2: +1}  # left = towards lane 0 (smaller y) for cars driving +x
MERGE_RELATIONS = ["none", "in_front", "behind"]
LANE_WIDTH_M = StraightLane.DEFAULT_WIDTH
CAR_LENGTH_M = Vehicle.LENGTH
CAR_WIDTH_M = Vehicle.WIDTH
ARRIVED_TOLERANCE_M = 0.5  # lateral offset to the target lane centre that counts as arrived
START_X_M = 200.0  # world x of the human at t = 0; the road is 10 km long
RangeF = tuple[float, float]
RangeI = tuple[int, int]


class MpcSettings(StrictModel):
    """Sampling-MPC sizes; the prediction integrates the bicycle model in sub-steps."""

    # policy steps (>= 1) each car's MPC plans ahead; longer plans see merges coming earlier and
    # cost more time
    horizon_steps: int = Field(6, ge=1)
    # candidate control sequences (>= 4) drawn per MPC iteration
    n_samples: int = Field(64, ge=4)
    # cross-entropy refinements (>= 1) of the sampling distribution per policy step
    iterations: int = Field(2, ge=1)
    # sub-steps (>= 1) of the bicycle model per policy step inside the MPC's prediction
    prediction_substeps: int = Field(2, ge=1)
    # the sampling spread around the warm start, as a fraction (> 0) of each control's range
    init_std_fraction: float = Field(0.1, gt=0)


class RewardWeights(StrictModel):
    """Per-step cost weights (the reward is their negative sum)."""

    # weight (>= 0) of (speed - target speed)^2, per (m/s)^2
    speed_per_mps2: float = Field(0.5, ge=0)
    # weight (>= 0) of (y - target lane centre)^2, per m^2: pulls the car into its target lane
    lane_lateral_per_m2: float = Field(1.0, ge=0)
    # weight (>= 0) of heading^2, per rad^2: keeps the car parallel to the road
    heading_per_rad2: float = Field(20.0, ge=0)
    # weight (>= 0) of acceleration^2, per (m/s^2)^2 (comfort)
    acceleration_per_mps2_sq: float = Field(0.05, ge=0)
    # weight (>= 0) of steering^2, per rad^2 (comfort)
    steering_per_rad2: float = Field(10.0, ge=0)
    # weight (>= 0) of the squared change of acceleration between steps (smoothness)
    acceleration_rate: float = Field(0.1, ge=0)
    # weight (>= 0) of the squared change of steering between steps (smoothness)
    steering_rate: float = Field(50.0, ge=0)
    # weight (>= 0) of the two cars' overlap area, m^2 (the predicted rectangles with a small
    # margin)
    collision: float = Field(2000.0, ge=0)
    # weight (>= 0) of the intrusion area, m^2, into the other car's clearance box
    # (clearance_longitudinal_m x clearance_lateral_m)
    clearance: float = Field(20.0, ge=0)
    # weight (>= 0) of the squared headway shortfall, m^2, of whichever car follows in the same lane
    headway: float = Field(5.0, ge=0)
    # weight (>= 0) of how far, in m, the car's body reaches beyond the road's outer edges
    offroad: float = Field(2000.0, ge=0)


class HighwayConfig(StrictModel):
    """Everything that shapes a Highway rollout; units in the key names."""

    # lanes of the straight road (>= 3), 4 m wide each, lane 0 on top
    lanes_count: int = Field(3, ge=3)
    # seconds (> 0) between two policy steps: the time step of the stored trajectories and of a
    # participant's clicks
    policy_dt_s: float = Field(0.5, gt=0)
    # highway-env's integration rate; policy_dt_s x this must be a whole number of sub-steps
    simulation_frequency_hz: int = Field(10, ge=1)
    # policy steps (>= 2) per rollout: the length of every stored trajectory
    episode_steps: int = Field(16, ge=2)
    # speed (m/s, >= 0) of the moving frame the positions are stored in; plus min_display_speed_mps
    # it must stay below the slowest car so cars drive forward on screen
    frame_speed_mps: float = Field(19.0, ge=0)
    # where the moving frame's origin starts, in m along the road relative to the cars' initial
    # midpoint (negative: behind them)
    frame_start_x_m: float = Field(-26.0)
    # slowest on-screen forward speed (m/s, >= 0) a car may show; a rollout with a slower car is
    # rejected as slow_on_screen
    min_display_speed_mps: float = Field(1.0, ge=0)
    # [low, high] range (m/s, >= 0) each car's start speed is drawn from, uniformly
    initial_speed_mps: RangeF = (22.5, 25.5)
    # [low, high] range (m/s, >= 0) each car's MPC target speed is drawn from, uniformly
    target_speed_mps: RangeF = (23.0, 25.0)
    # [low, high] range (m) of the robot's start x minus the human's, drawn uniformly
    initial_gap_m: RangeF = (-20.0, 20.0)
    # smallest start gap (m, >= 0) of two cars in the same lane; a smaller drawn gap is redrawn
    # beyond it
    min_same_lane_gap_m: float = Field(14.0, ge=0)
    # probability (0-1) that the human starts in the lane a merging robot aims for (else a random
    # lane)
    human_in_robot_target_lane_prob: float = Field(0.5, ge=0, le=1)
    # [low, high] range (policy steps, >= 0) each car waits before steering to its target lane,
    # drawn uniformly
    merge_delay_steps: RangeI = (0, 2)
    # largest acceleration or braking (m/s^2, > 0) the MPC may command
    max_acceleration_mps2: float = Field(3.0, gt=0)
    # largest steering angle (rad, > 0) the MPC may command
    max_steering_rad: float = Field(0.08, gt=0)
    # extra length (m, >= 0) beyond the car's own of the clearance box the reward keeps free
    clearance_longitudinal_m: float = Field(4.0, ge=0)
    # extra width (m, >= 0) beyond the car's own of the clearance box; also how close laterally
    # counts as the same lane for headway
    clearance_lateral_m: float = Field(1.0, ge=0)
    # the time gap (s, >= 0) a following car keeps: a gap shorter than this x its speed is penalised
    headway_time_s: float = Field(0.8, ge=0)
    # half the view's length along the road (m, > 0); a rollout where a car leaves it is rejected as
    # out_of_view
    view_half_length_m: float = Field(45.0, gt=0)
    # how far (m, >= 0) a car may stray outside its start-to-target lane corridor before the rollout
    # is rejected as swerve
    max_lane_excursion_m: float = Field(1.0, ge=0)
    # the sampling MPC's sizes, the same for both cars
    mpc: MpcSettings = MpcSettings()
    # the per-step cost weights both cars' MPC minimises
    reward: RewardWeights = RewardWeights()

    @model_validator(mode="after")
    def _check(self) -> "HighwayConfig":
        for name in ("initial_speed_mps", "target_speed_mps", "initial_gap_m",
                     "merge_delay_steps"):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"{name}: low {low} is above high {high}")
        for name in ("initial_speed_mps", "target_speed_mps", "merge_delay_steps"):
            if getattr(self, name)[0] < 0:
                raise ValueError(f"{name}: must not be negative")
        slowest = min(self.initial_speed_mps[0], self.target_speed_mps[0])
        if self.frame_speed_mps + self.min_display_speed_mps > slowest:
            raise ValueError(f"frame_speed_mps: {self.frame_speed_mps} m/s plus "
                             f"min_display_speed_mps must stay below the slowest car "
                             f"({slowest} m/s), or cars drift backwards on screen")
        substeps = self.policy_dt_s * self.simulation_frequency_hz
        if abs(substeps - round(substeps)) > 1e-9 or round(substeps) < 1:
            raise ValueError("simulation_frequency_hz: policy_dt_s must be a whole number "
                             "of simulation steps")
        return self


@dataclass
class Driver:
    """One car and what its MPC is steering towards."""

    vehicle: Vehicle
    start_y: float
    target_y: float
    target_speed: float
    delay_steps: int
    plan: np.ndarray
    last_control: np.ndarray
    mpc_driven: bool = True

    def lane_target(self, step: int) -> float:
        """The lane centre it aims for at `step` (its start lane until the merge delay ends)."""
        return self.target_y if step >= self.delay_steps else self.start_y


class HighwayWorld:
    """The Highway world: see the module docstring for road, frame and agents."""

    name = "highway"
    robot_label = "robot_intent"
    starts_as_recorded = False

    def __init__(self, config: HighwayConfig) -> None:
        self.config = config
        lanes = [f"lane_{k}" for k in range(config.lanes_count)]
        self.label_names = {
            "robot_intent": INTENTS, "human_intent": INTENTS,
            "robot_final_lane": lanes, "human_final_lane": lanes,
            "robot_merged_into_human_lane": ["no", "yes"], "merge_relation": MERGE_RELATIONS,
        }  # also per-trajectory ints without classes: robot/human_change_step (-1 = keep),
        # robot_target_speed_cmps
        self.dt_s = config.policy_dt_s
        self.substeps = round(config.policy_dt_s * config.simulation_frequency_hz)
        self.network = RoadNetwork.straight_road_network(config.lanes_count, speed_limit=30)
        self.road_top_m = -LANE_WIDTH_M / 2
        self.road_bottom_m = (config.lanes_count - 0.5) * LANE_WIDTH_M
        self.mpc = SamplingMPC(
            horizon=config.mpc.horizon_steps, n_samples=config.mpc.n_samples,
            control_low=(-config.max_acceleration_mps2, -config.max_steering_rad),
            control_high=(config.max_acceleration_mps2, config.max_steering_rad),
            iterations=config.mpc.iterations, init_std_fraction=config.mpc.init_std_fraction)

    @classmethod
    def from_yaml(cls, path: Path) -> "HighwayWorld":
        """Build from a YAML file typed by `HighwayConfig`."""
        return cls(load_yaml_model(path, HighwayConfig))

    def prepare(self, layout: Layout) -> None:
        """Nothing to set up: both cars run the sampling MPC, which needs no training."""

    def scene(self) -> Scene:
        """Lanes, view bounds and car shapes in the moving frame."""
        c = self.config
        half = c.view_half_length_m
        return Scene(
            world=self.name, dt_s=self.dt_s, frame_speed_mps=c.frame_speed_mps,
            frame=(f"x [m] along the road relative to a camera point that starts "
                   f"{-c.frame_start_x_m} m behind the two cars' initial midpoint and moves "
                   f"forward at a constant {c.frame_speed_mps} m/s, slower than every car; "
                   f"y [m] is highway-env's lateral coordinate (lane 0 on top, y grows "
                   f"downwards); cars drive towards +x; dt = {self.dt_s} s per step, "
                   f"{c.episode_steps} steps per interaction"),
            bounds=Bounds(x_min_m=-half, x_max_m=half, y_min_m=self.road_top_m - 1.0,
                          y_max_m=self.road_bottom_m + 1.0),
            lanes=[Lane(index=k, y_center_m=k * LANE_WIDTH_M, width_m=LANE_WIDTH_M)
                   for k in range(c.lanes_count)],
            agents=[AgentShape(name="robot", kind="car", length_m=CAR_LENGTH_M,
                               width_m=CAR_WIDTH_M, color=ROBOT_COLOR),
                    AgentShape(name="human", kind="car", length_m=CAR_LENGTH_M,
                               width_m=CAR_WIDTH_M, color=HUMAN_COLOR)])

    # ----- one rollout -------------------------------------------------------------------

    def rollout(self, rng: np.random.Generator) -> Episode:
        """One two-car interaction; raises Rejected on collision, off-road or unfinished merge."""
        setup = self._draw_setup(rng)
        road, drivers = self._place_cars(setup)
        origin_x = START_X_M + setup["gap"] / 2 - self.config.frame_start_x_m
        states = [self._snapshot(drivers, origin_x, 0)]
        for step in range(self.config.episode_steps):
            self._advance(road, drivers, step, rng, check=True)
            states.append(self._snapshot(drivers, origin_x, step + 1))
        positions = np.array([s[0] for s in states])
        self._check_view(positions)
        self._check_moves_forward(np.array([s[1] for s in states]),
                                  np.array([s[2] for s in states]))
        self._check_merges_done(drivers)
        self._check_no_swerve(positions, drivers)
        labels = self._labels(setup, positions)
        return Episode(positions=positions, headings=np.array([s[1] for s in states]),
                       speeds=np.array([s[2] for s in states]), labels=labels)

    def _draw_setup(self, rng: np.random.Generator) -> dict:
        """Robot intent first (uniform), then a start lane where it is feasible, then the human."""
        c = self.config
        robot_intent = int(rng.integers(3))
        robot_lane = int(rng.choice(self._feasible_lanes(robot_intent)))
        robot_target = robot_lane + LANE_SHIFT[robot_intent]
        if robot_intent != 0 and rng.random() < c.human_in_robot_target_lane_prob:
            human_lane = robot_target
        else:
            human_lane = int(rng.integers(c.lanes_count))
        human_intent = int(rng.choice(self._feasible_intents(human_lane)))
        gap = float(rng.uniform(*c.initial_gap_m))
        if human_lane == robot_lane and abs(gap) < c.min_same_lane_gap_m:
            widest = max(c.min_same_lane_gap_m, *(abs(v) for v in c.initial_gap_m))
            gap = float(np.copysign(rng.uniform(c.min_same_lane_gap_m, widest), gap))
        delays = rng.integers(c.merge_delay_steps[0], c.merge_delay_steps[1] + 1, size=2)
        return {
            "intent": (robot_intent, human_intent),
            "lane": (robot_lane, human_lane),
            "target_lane": (robot_target, human_lane + LANE_SHIFT[human_intent]),
            "gap": gap,
            "speed": tuple(float(v) for v in rng.uniform(*c.initial_speed_mps, size=2)),
            "target_speed": tuple(float(v) for v in rng.uniform(*c.target_speed_mps, size=2)),
            "delay": tuple(int(d) for d in delays),
        }

    def _feasible_lanes(self, intent: int) -> list[int]:
        return [k for k in range(self.config.lanes_count) if self._stays_on_road(k, intent)]

    def _feasible_intents(self, lane: int) -> list[int]:
        return [i for i in range(len(INTENTS)) if self._stays_on_road(lane, i)]

    def _stays_on_road(self, lane: int, intent: int) -> bool:
        return 0 <= lane + LANE_SHIFT[intent] < self.config.lanes_count

    def _place_cars(self, setup: dict) -> tuple[Road, list[Driver]]:
        road = Road(network=self.network, np_random=np.random.RandomState(0),
                    record_history=False)
        xs = (START_X_M + setup["gap"], START_X_M)
        drivers = []
        for agent in (0, 1):
            y = setup["lane"][agent] * LANE_WIDTH_M
            vehicle = Vehicle(road, [xs[agent], y], heading=0.0, speed=setup["speed"][agent])
            road.vehicles.append(vehicle)
            drivers.append(Driver(
                vehicle=vehicle, start_y=y, target_y=setup["target_lane"][agent] * LANE_WIDTH_M,
                target_speed=setup["target_speed"][agent], delay_steps=setup["delay"][agent],
                plan=self.mpc.initial_plan(), last_control=np.zeros(2)))
        return road, drivers

    def _advance(self, road: Road, drivers: list[Driver], step: int,
                 rng: np.random.Generator, check: bool) -> None:
        """Plan each MPC-driven car, then integrate the road for one policy step."""
        controls = []
        for me, other in ((drivers[0], drivers[1]), (drivers[1], drivers[0])):
            if not me.mpc_driven:
                controls.append(None)
                continue
            cost = self._cost_fn(me, other, me.lane_target(step))
            me.plan = self.mpc.plan(cost, self.mpc.shift(me.plan), rng)
            me.last_control = me.plan[0].copy()
            controls.append(me.last_control)
        for driver, control in zip(drivers, controls, strict=True):
            if control is not None:
                driver.vehicle.act({"acceleration": float(control[0]),
                                    "steering": float(control[1])})
        sim_dt = 1.0 / self.config.simulation_frequency_hz
        for _ in range(self.substeps):
            road.step(sim_dt)
            if check:
                self._check_safe(drivers)

    def _check_safe(self, drivers: list[Driver]) -> None:
        for driver in drivers:
            if driver.vehicle.crashed or driver.vehicle.impact is not None:
                raise Rejected("collision")
            if not self._body_on_road(driver.vehicle):
                raise Rejected("offroad")

    def _body_on_road(self, vehicle: Vehicle) -> bool:
        """All four corners of the car's rectangle lie between the road's outer edges."""
        heading = float(vehicle.heading)
        reach = (CAR_WIDTH_M / 2 * abs(np.cos(heading))
                 + CAR_LENGTH_M / 2 * abs(np.sin(heading)))
        y = float(vehicle.position[1])
        return self.road_top_m <= y - reach and y + reach <= self.road_bottom_m

    def _check_view(self, positions: np.ndarray) -> None:
        limit = self.config.view_half_length_m - CAR_LENGTH_M / 2
        if np.abs(positions[..., 0]).max() > limit:
            raise Rejected("out_of_view")

    def _check_moves_forward(self, headings: np.ndarray, speeds: np.ndarray) -> None:
        """Both cars must visibly drive forward on screen at every step of the clip."""
        shown = speeds * np.cos(headings) - self.config.frame_speed_mps
        if shown.min() < self.config.min_display_speed_mps:
            raise Rejected("slow_on_screen")

    def _check_merges_done(self, drivers: list[Driver]) -> None:
        for driver in drivers:
            if abs(driver.vehicle.position[1] - driver.target_y) >= ARRIVED_TOLERANCE_M:
                raise Rejected("merge_incomplete")

    def _check_no_swerve(self, positions: np.ndarray, drivers: list[Driver]) -> None:
        """Evasive swerves out of the start-to-target corridor would blur the intent labels."""
        for agent, driver in enumerate(drivers):
            low = min(driver.start_y, driver.target_y) - self.config.max_lane_excursion_m
            high = max(driver.start_y, driver.target_y) + self.config.max_lane_excursion_m
            ys = positions[:, agent, 1]
            if ys.min() < low or ys.max() > high:
                raise Rejected("swerve")

    def _snapshot(self, drivers: list[Driver], origin_x: float, step: int):
        """(positions [2,2] in the moving frame, headings [2], world speeds [2]) now."""
        shift = origin_x + self.config.frame_speed_mps * step * self.dt_s
        pos = np.array([[d.vehicle.position[0] - shift, d.vehicle.position[1]] for d in drivers])
        headings = np.array([wrap_to_pi(d.vehicle.heading) for d in drivers])
        speeds = np.array([d.vehicle.speed for d in drivers])
        return pos, headings, speeds

    # ----- the MPC cost ------------------------------------------------------------------

    def _cost_fn(self, me: Driver, other: Driver, target_y: float):
        """cost(controls[K,H,2]) -> [K]: `me` rolls out the bicycle model, `other` moves at
        constant velocity."""
        w = self.config.reward
        n_sub = self.config.mpc.prediction_substeps
        ego = me.vehicle
        start = (float(ego.position[0]), float(ego.position[1]), float(ego.heading),
                 float(ego.speed))
        other_pos, other_vel = other.vehicle.position.copy(), other.vehicle.velocity
        other_speed = float(other.vehicle.speed)
        last = me.last_control

        def cost(controls: np.ndarray) -> np.ndarray:
            horizon = controls.shape[1]
            accel, steer = controls[..., 0], controls[..., 1]
            rates = np.diff(controls, axis=1, prepend=np.broadcast_to(last, (len(controls), 1, 2)))
            accel_rate, steer_rate = rates[..., 0], rates[..., 1]
            comfort = (w.acceleration_per_mps2_sq * accel * accel
                       + w.steering_per_rad2 * steer * steer
                       + w.acceleration_rate * accel_rate * accel_rate
                       + w.steering_rate * steer_rate * steer_rate)
            x, y, psi, v = self._predict(start, controls, n_sub)
            t = self.dt_s * np.arange(1, horizon + 1)
            dx = x - (other_pos[0] + other_vel[0] * t)
            dy = y - (other_pos[1] + other_vel[1] * t)
            steps = self._step_cost(dx, dy, y, psi, v, other_speed, target_y, me.target_speed)
            return (comfort + steps).sum(1)

        return cost

    def _predict(self, start: tuple, controls: np.ndarray, n_sub: int):
        """Euler-integrate highway-env's bicycle model for all candidates at once.

        Same update order as `Vehicle.step` (position, then heading, then speed), written as
        cumulative sums over the H * n_sub sub-steps; returns x, y, heading, speed [K, H] at
        the end of each policy step."""
        x0, y0, psi0, v0 = start
        dt = self.dt_s / n_sub
        accel = np.repeat(controls[..., 0], n_sub, axis=1)
        beta_steps = np.arctan(0.5 * np.tan(controls[..., 1]))
        beta = np.repeat(beta_steps, n_sub, axis=1)
        sin_beta = np.repeat(np.sin(beta_steps), n_sub, axis=1)
        v_before = v0 + dt * (np.cumsum(accel, 1) - accel)
        turn = v_before * sin_beta / (CAR_LENGTH_M / 2)
        psi_before = psi0 + dt * (np.cumsum(turn, 1) - turn)
        course = psi_before + beta
        x = x0 + dt * np.cumsum(v_before * np.cos(course), 1)
        y = y0 + dt * np.cumsum(v_before * np.sin(course), 1)
        ends = slice(n_sub - 1, None, n_sub)
        v_after = v_before + dt * accel
        psi_after = psi_before + dt * turn
        return x[:, ends], y[:, ends], psi_after[:, ends], v_after[:, ends]

    def _step_cost(self, dx, dy, y, psi, v, other_speed, target_y, target_speed):
        """Reward terms at each predicted step, for all candidates ([K, H] arrays)."""
        c, w = self.config, self.config.reward
        top = self.road_top_m + CAR_WIDTH_M / 2
        bottom = self.road_bottom_m - CAR_WIDTH_M / 2
        abs_dx, abs_dy = np.abs(dx), np.abs(dy)
        tilt = CAR_LENGTH_M / 2 * np.abs(np.sin(psi))  # extra lateral reach of a turned car
        overlap = (np.maximum(CAR_LENGTH_M + 0.5 - abs_dx, 0)
                   * np.maximum(CAR_WIDTH_M + 0.3 + tilt - abs_dy, 0))
        near = (np.maximum(CAR_LENGTH_M + c.clearance_longitudinal_m - abs_dx, 0)
                * np.maximum(CAR_WIDTH_M + c.clearance_lateral_m - abs_dy, 0))
        same_lane = abs_dy < CAR_WIDTH_M + c.clearance_lateral_m
        gap = abs_dx - CAR_LENGTH_M
        follower_speed = np.where(dx < 0, v, other_speed)  # whoever is behind needs headway
        short = np.maximum(c.headway_time_s * follower_speed - gap, 0) * same_lane
        off = np.maximum(top - y + tilt, 0) + np.maximum(y + tilt - bottom, 0)
        return (w.speed_per_mps2 * (v - target_speed) ** 2
                + w.lane_lateral_per_m2 * (y - target_y) ** 2
                + w.heading_per_rad2 * psi**2
                + w.collision * overlap + w.clearance * near + w.headway * short**2
                + w.offroad * off)

    # ----- labels ------------------------------------------------------------------------

    def _labels(self, setup: dict, positions: np.ndarray) -> dict[str, int]:
        robot_intent, human_intent = setup["intent"]
        robot_target_y = setup["target_lane"][0] * LANE_WIDTH_M
        robot_change = self._arrival_step(positions[:, 0, 1], robot_target_y, robot_intent)
        human_change = self._arrival_step(positions[:, 1, 1],
                                          setup["target_lane"][1] * LANE_WIDTH_M, human_intent)
        merged = robot_change >= 0 and self._lane_of(positions[robot_change, 1, 1]) == \
            setup["target_lane"][0]
        relation = 0
        if merged:
            relation = 1 if positions[-1, 0, 0] > positions[-1, 1, 0] else 2
        return {
            "robot_intent": robot_intent,
            "human_intent": human_intent,
            "robot_final_lane": self._lane_of(positions[-1, 0, 1]),
            "human_final_lane": self._lane_of(positions[-1, 1, 1]),
            "robot_merged_into_human_lane": int(merged),
            "merge_relation": relation,
            "robot_change_step": robot_change,
            "human_change_step": human_change,
            "robot_target_speed_cmps": round(setup["target_speed"][0] * 100),
        }

    @staticmethod
    def _arrival_step(ys: np.ndarray, target_y: float, intent: int) -> int:
        """First step whose lateral offset to the target lane centre is below tolerance."""
        if intent == 0:
            return -1
        arrived = np.flatnonzero(np.abs(ys - target_y) < ARRIVED_TOLERANCE_M)
        return int(arrived[0]) if len(arrived) else -1

    def _lane_of(self, y: float) -> int:
        return int(np.clip(np.rint(y / LANE_WIDTH_M), 0, self.config.lanes_count - 1))

    # ----- ground truth for the study ----------------------------------------------------

    def robot_policy_actions(self, positions: np.ndarray, robot_heading: float,
                             robot_speed: float, human_velocity: np.ndarray, labels: dict,
                             n_steps: int, rng: np.random.Generator) -> np.ndarray:
        """The robot's own MPC from an arbitrary start (scene frame), the human at constant
        velocity; returns the robot's actions [n_steps, 2] in the scene frame."""
        positions = np.asarray(positions, dtype=np.float64)
        road = Road(network=self.network, np_random=np.random.RandomState(0),
                    record_history=False)
        origin_x = START_X_M
        world = positions.copy()
        world[:, 0] += origin_x
        human_world_v = np.asarray(human_velocity, dtype=np.float64) + [self.config.frame_speed_mps,
                                                                          0.0]
        robot = Vehicle(road, world[0], heading=float(robot_heading), speed=float(robot_speed))
        human = Vehicle(road, world[1], heading=float(np.arctan2(human_world_v[1],
                                                                 human_world_v[0])),
                        speed=float(np.hypot(*human_world_v)))
        road.vehicles.extend([robot, human])
        target_lane = self._policy_target_lane(positions[0, 1], labels)
        target_speed = labels.get("robot_target_speed_cmps", robot_speed * 100) / 100
        drivers = [
            Driver(robot, start_y=world[0, 1], target_y=target_lane * LANE_WIDTH_M,
                   target_speed=float(target_speed), delay_steps=0,
                   plan=self.mpc.initial_plan(), last_control=np.zeros(2)),
            Driver(human, start_y=world[1, 1], target_y=world[1, 1], target_speed=human.speed,
                   delay_steps=0, plan=self.mpc.initial_plan(), last_control=np.zeros(2),
                   mpc_driven=False),
        ]
        track = [self._snapshot(drivers, origin_x, 0)[0][0]]
        for step in range(n_steps):
            self._advance(road, drivers, step, rng, check=False)
            human.position = world[1] + human_world_v * (step + 1) * self.dt_s
            track.append(self._snapshot(drivers, origin_x, step + 1)[0][0])
        return np.diff(np.array(track), axis=0) / self.dt_s

    def _policy_target_lane(self, robot_y: float, labels: dict) -> int:
        if "robot_final_lane" in labels:
            return int(labels["robot_final_lane"])
        lane = self._lane_of(robot_y) + LANE_SHIFT[int(labels.get("robot_intent", 0))]
        return int(np.clip(lane, 0, self.config.lanes_count - 1))

    # ----- segments and start states for the trial bank ---------------------------------

    def visible_ends(self, robot_track: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Before the lane change completes (5-75% of the way across), or in the first 60% of
        the interaction when the robot keeps its lane."""
        shift = robot_track[:, 1] - robot_track[0, 1]
        total = shift[-1]
        if abs(total) > 0.5 * LANE_WIDTH_M:
            done = shift[ends] / total
            return ends[(done >= 0.05) & (done <= 0.75)]
        return ends[ends <= 0.6 * (len(robot_track) - 1)]

    def data_start_candidates(self, scene: Scene, segment: np.ndarray, covered: Covered,
                              reach: float) -> dict[str, np.ndarray]:
        """`same_lane` and `adjacent_lane` states (indices into `covered`; lanes by nearest
        centre) within `reach` along the road, with `reach` of road ahead (the way the robot's
        last segment move goes along x) inside the view; not within two car lengths along and
        half a lane across of the human."""
        robot, human, pts = segment[-1, ROBOT], segment[-1, HUMAN], covered.positions
        travel = 1.0 if segment[-1, ROBOT, 0] >= segment[-2, ROBOT, 0] else -1.0
        centres = np.array([lane.y_center_m for lane in scene.lanes])
        index = np.array([lane.index for lane in scene.lanes])
        lane_of = index[np.argmin(np.abs(pts[:, 1, None] - centres), axis=1)]
        robot_lane = index[np.argmin(np.abs(robot[1] - centres))]
        half_lane = scene.lanes[0].width_m / 2
        car = max(a.length_m for a in scene.agents)
        clear = ~((np.abs(pts[:, 0] - human[0]) < 2 * car)
                  & (np.abs(pts[:, 1] - human[1]) < half_lane))
        ahead = pts[:, 0] + travel * reach
        b = scene.bounds
        keep = (clear & (np.abs(pts[:, 0] - robot[0]) <= reach)
                & (ahead > b.x_min_m) & (ahead < b.x_max_m))
        gap = np.abs(lane_of - robot_lane)
        return {"same_lane": np.flatnonzero(keep & (gap == 0)),
                "adjacent_lane": np.flatnonzero(keep & (gap == 1))}
