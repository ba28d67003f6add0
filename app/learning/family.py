"""Train a model family: every seed of Ours and the VAE for a world, several processes at once.

A study's claims are about Ours vs the VAE, not about one training run, so its bundle holds
several seeds of each (the study config's `models.seeds`). Each job is `train_world`, the
pipeline's train stage, on one thread; the jobs of a phase run `workers` at a time. Seed k's
VAE takes its k-means k from seed k's Ours, so every Ours seed is trained first. A checkpoint
that already exists is kept, so an interrupted build resumes where it stopped.
"""

from collections.abc import Callable
from pathlib import Path

from app.layout import Layout
from app.learning.config import TrainConfig
from app.learning.jobs import JobPool, job_pool

Job = tuple[str, str, int]  # world, model, seed


def missing_jobs(layout: Layout, worlds: list[str], seeds: list[int], model: str) -> list[Job]:
    """The (world, model, seed) checkpoints of one model that do not exist yet."""
    return [(world, model, seed) for world in worlds for seed in seeds
            if not layout.checkpoint(world, model, seed).is_file()]


def train_family(layout: Layout, worlds: list[str], seeds: list[int], cfg: TrainConfig,
                 workers: int | JobPool = 2, say: Callable[[str], None] = print) -> list[Job]:
    """Train every missing checkpoint of Ours then the VAE for `worlds` x `seeds` (on a pool
    of `workers`, or on the pool given); returns the jobs it ran."""
    ran = []
    with job_pool(workers) as pool:
        for model in ("ours", "vae"):
            jobs = missing_jobs(layout, worlds, seeds, model)
            kept = len(worlds) * len(seeds) - len(jobs)
            say(f"training {len(jobs)} {model} checkpoint(s) on {pool.workers} process(es); "
                f"{kept} already exist")
            pool.run(train_job, [(layout, job, cfg) for job in jobs], "train family", "model")
            ran += jobs
    return ran


def train_job(layout: Layout, job: Job, cfg: TrainConfig) -> Path:
    """One checkpoint: `train_world` for (world, model, seed) into the layout's place."""
    from app.learning.train import train_world

    world, model, seed = job
    return train_world(layout, world, model, seed, cfg, progress=False)
