"""Roll out a world many times, in parallel and reproducibly, into one trajectory file."""

import multiprocessing as mp
import os
import platform
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

import app
from app.configio import ConfigError
from app.core.files import sha256_file, write_json
from app.data.trajectory import Episode, Rejected, TrajectorySet
from app.layout import Layout
from app.worlds.registry import SimulatedWorld, World, build_world

MAX_ATTEMPTS = 50
_WORKER_WORLD: World | None = None


@dataclass
class SimulationResult:
    """Where the data went and what happened on the way."""

    npz_path: Path
    meta_path: Path
    meta: dict


def episode_rng(seed: int, index: int, attempt: int) -> np.random.Generator:
    """Independent stream per (seed, trajectory, attempt): output never depends on workers."""
    return np.random.default_rng(np.random.SeedSequence([seed, index, attempt]))


def _init_worker(world: str, config_path: Path | None, policy: str) -> None:
    global _WORKER_WORLD
    if policy == "sac":  # only the SAC policy needs torch; importing it costs ~3 s per worker
        import torch

        torch.set_num_threads(1)
    _WORKER_WORLD = build_world(world, config_path, policy)


def _roll_one(args: tuple[int, int]) -> tuple[Episode | None, Counter]:
    seed, index = args
    rejections: Counter = Counter()
    for attempt in range(MAX_ATTEMPTS):
        try:
            return _WORKER_WORLD.rollout(episode_rng(seed, index, attempt)), rejections
        except Rejected as why:
            rejections[str(why)] += 1
    return None, rejections


def simulate(world: str, n: int, seed: int, layout: Layout, config_path: Path | None = None,
             policy: str = "mpc", workers: int | None = None) -> SimulationResult:
    """Simulate `n` kept trajectories of `world` and write them with a meta.json."""
    started = time.perf_counter()
    built = build_world(world, config_path, policy)  # validates config before forking
    if not isinstance(built, SimulatedWorld):
        raise ConfigError(f"world: {world} is a recorded world; `tomstudy import-recordings "
                          f"{world}` reads its recordings")
    built.prepare(layout)  # e.g. train the SAC policy once, in the parent
    workers = workers or min(2, os.cpu_count() or 1)
    episodes, rejections = _run_pool(world, config_path, policy, n, seed, workers)
    if any(ep is None for ep in episodes):
        raise RuntimeError(f"{world}: some trajectories were rejected {MAX_ATTEMPTS} times: "
                           f"{dict(rejections)}")
    trajs = TrajectorySet.from_episodes(world, built.dt_s, episodes, built.label_names,
                                        built.scene())
    npz_path, meta_path = layout.trajectories(world), layout.trajectories_meta(world)
    trajs.save(npz_path)
    meta = _meta(built, trajs, n, seed, policy, workers, rejections,
                 time.perf_counter() - started, npz_path)
    write_json(meta_path, meta)
    return SimulationResult(npz_path, meta_path, meta)


def _run_pool(world, config_path, policy, n, seed, workers):
    jobs = [(seed, i) for i in range(n)]
    episodes: list[Episode | None] = []
    rejections: Counter = Counter()
    bar = tqdm(total=n, desc=f"simulate {world}", unit="traj")
    if workers == 1:
        _init_worker(world, config_path, policy)
        results = map(_roll_one, jobs)
        pool = None
    else:
        pool = mp.get_context("fork").Pool(workers, _init_worker, (world, config_path, policy))
        results = pool.imap(_roll_one, jobs, chunksize=8)
    try:
        for episode, rejected in results:
            episodes.append(episode)
            rejections.update(rejected)
            bar.update()
    finally:
        bar.close()
        if pool is not None:
            pool.terminate()
    return episodes, rejections


def _meta(world: World, trajs: TrajectorySet, n, seed, policy, workers, rejections,
          wall_s, npz_path) -> dict:
    return {
        "world": world.name,
        "config": world.config.model_dump(),
        "seed": seed,
        "n": n,
        "policy": policy,
        "dt_s": world.dt_s,
        "max_steps": int(trajs.positions.shape[1] - 1),
        "mean_length_steps": float(trajs.lengths.mean()),
        "label_counts": trajs.label_counts(),
        "rejected": dict(sorted(rejections.items())),
        "attempts": n + sum(rejections.values()),
        "workers": workers,
        "wall_time_s": round(wall_s, 2),
        "frame": trajs.scene.frame,
        "package_version": app.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "content_sha256": sha256_file(npz_path),
    }
