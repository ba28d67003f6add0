"""Train a model family: every seed of Ours and the VAE for a world, several processes at once.

A study's claims are about Ours vs the VAE, not about one training run, so its bundle holds
several seeds of each (the study config's `models.seeds`). Each job is `train_world`, the
pipeline's train stage, on one thread; the jobs of a phase run `workers` at a time. Seed k's
VAE takes its k-means k from seed k's Ours, so every Ours seed is trained first. A checkpoint
that already exists is kept, so an interrupted build resumes where it stopped.
"""

import multiprocessing as mp
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from tqdm import tqdm

from app.layout import Layout
from app.learning.config import TrainConfig

Job = tuple[str, str, int]  # world, model, seed


def missing_jobs(layout: Layout, worlds: list[str], seeds: list[int], model: str) -> list[Job]:
    """The (world, model, seed) checkpoints of one model that do not exist yet."""
    return [(world, model, seed) for world in worlds for seed in seeds
            if not layout.checkpoint(world, model, seed).is_file()]


def train_family(layout: Layout, worlds: list[str], seeds: list[int], cfg: TrainConfig,
                 workers: int = 2, say: Callable[[str], None] = print) -> list[Job]:
    """Train every missing checkpoint of Ours then the VAE for `worlds` x `seeds`; returns
    the jobs it ran."""
    ran = []
    for model in ("ours", "vae"):
        jobs = missing_jobs(layout, worlds, seeds, model)
        kept = len(worlds) * len(seeds) - len(jobs)
        say(f"training {len(jobs)} {model} checkpoint(s) on {workers} process(es); "
            f"{kept} already exist")
        run_jobs(layout, jobs, cfg, workers)
        ran += jobs
    return ran


def run_jobs(layout: Layout, jobs: list[Job], cfg: TrainConfig, workers: int) -> None:
    """Run training jobs `workers` at a time with one progress bar (in process if 1)."""
    bar = tqdm(total=len(jobs), desc="train family", unit="model", disable=not jobs)
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            train_job(layout, job, cfg)
            bar.update(1)
    else:
        # spawn, not fork: a forked child of a process that has run torch can deadlock
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
            futures = [pool.submit(train_job, layout, job, cfg) for job in jobs]
            for done in as_completed(futures):
                done.result()  # re-raises a job's error here
                bar.update(1)
    bar.close()


def train_job(layout: Layout, job: Job, cfg: TrainConfig) -> Path:
    """One checkpoint: `train_world` for (world, model, seed) into the layout's place."""
    from app.learning.train import train_world

    world, model, seed = job
    return train_world(layout, world, model, seed, cfg, progress=False)
