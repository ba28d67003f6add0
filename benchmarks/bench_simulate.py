"""Wall time of `simulate(world, n, seed 0, workers=2)` for every world, beside raw highway-env.

The baseline, measured in the same run, steps `highway-v0` with 2 controlled vehicles, no
traffic, the Highway world's simulation / policy frequencies and zero actions (a
MultiAgentAction tuple), for the same total number of policy steps as the kept trajectories,
split over the same number of processes. Its observation is per-agent Kinematics with
`normalize: False` (the cheapest observation highway-v0 offers for two agents).

    .venv/bin/python benchmarks/bench_simulate.py [--n 2000] [--worlds highway obstacle]
"""

import argparse
import multiprocessing as mp
import tempfile
import time
import warnings

import numpy as np

from app.data.trajectory import TrajectorySet
from app.layout import Layout
from app.worlds.registry import SIMULATED_WORLDS, build_world
from app.worlds.simulate import simulate

WORKERS = 2


def raw_env_steps(args: tuple[int, int, int]) -> int:
    """Step highway-v0 with zero actions `n_steps` times (resetting when an episode ends)."""
    n_steps, sim_hz, policy_hz = args
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers highway-v0)

    warnings.filterwarnings("ignore")
    env = gym.make("highway-v0", config={
        "controlled_vehicles": 2, "vehicles_count": 0,
        "simulation_frequency": sim_hz, "policy_frequency": policy_hz,
        "action": {"type": "MultiAgentAction", "action_config": {"type": "ContinuousAction"}},
        "observation": {"type": "MultiAgentObservation",
                        "observation_config": {"type": "Kinematics", "normalize": False}},
    })
    env.reset(seed=0)
    zeros = tuple(np.zeros(2, dtype=np.float32) for _ in range(2))
    for _ in range(n_steps):
        _, _, terminated, truncated, _ = env.step(zeros)
        if terminated or truncated:
            env.reset()
    env.close()
    return n_steps


def time_raw_highway_env(total_steps: int, sim_hz: int, policy_hz: int) -> float:
    """Wall seconds for `total_steps` raw env steps split over WORKERS processes."""
    shares = [total_steps // WORKERS + (k < total_steps % WORKERS) for k in range(WORKERS)]
    started = time.perf_counter()
    with mp.get_context("fork").Pool(WORKERS) as pool:
        done = sum(pool.map(raw_env_steps, [(s, sim_hz, policy_hz) for s in shares]))
    assert done == total_steps
    return time.perf_counter() - started


def main() -> None:
    """Time each world's simulation and the raw-stepping baseline; print ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument("--worlds", nargs="+", default=list(SIMULATED_WORLDS))
    args = parser.parse_args()
    highway = build_world("highway")
    sim_hz = highway.config.simulation_frequency_hz
    policy_hz = round(1 / highway.dt_s)
    baselines: dict[int, float] = {}
    rows = []
    for world in args.worlds:
        with tempfile.TemporaryDirectory() as tmp:
            started = time.perf_counter()
            result = simulate(world, args.n, seed=0, layout=Layout(tmp), workers=WORKERS)
            wall = time.perf_counter() - started
            steps = int(TrajectorySet.load(result.npz_path).lengths.sum())
        if steps not in baselines:
            baselines[steps] = time_raw_highway_env(steps, sim_hz, policy_hz)
        rows.append((world, wall, steps, baselines[steps], result.meta["attempts"]))
    print(f"\n{'world':<10}{'n':>6}{'steps':>8}{'attempts':>10}{'simulate_s':>12}"
          f"{'raw_env_s':>11}{'ratio':>8}")
    for world, wall, steps, raw, attempts in rows:
        print(f"{world:<10}{args.n:>6}{steps:>8}{attempts:>10}{wall:>12.1f}{raw:>11.1f}"
              f"{wall / raw:>8.2f}")
    print(f"(raw_env_s: highway-v0, 2 controlled cars, {sim_hz} Hz physics, {policy_hz} Hz "
          f"actions, zero actions, {WORKERS} processes; ratio = simulate_s / raw_env_s)")


if __name__ == "__main__":
    main()
