"""Train time per model per world, and one study trial's inference time vs bare numpy.

Run: .venv/bin/python benchmarks/bench_train.py [--worlds highway obstacle] [--models ours vae]
Simulates var/data/<world>/trajectories.npz first where it is missing (what `make data` does;
a fresh clone after `make serve` has none: the served bundle ships no trajectories). Prints:
- wall time of `train_and_save` (default training.yaml) per model and world; target < 60 s
  (the VAE's k-means k: the codes of the Ours trained before it, else of the primary Ours of
  the bundle the paper study is served from)
  on 2000 trajectories (its CPU time and the load average are printed too: on a machine
  shared with other jobs, wall time overstates the cost);
- one trial (encode one segment, predict n steps from 5 states) through `TrainedModel.trial`,
  as a ratio to a plain-numpy forward of the same weights measured in the same run
  (target <= 3x); the torch forward (inference_mode) of the same trial for reference.
"""

import argparse
import os
import sys
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np
import torch

from app.bank.prepare import ensure_trajectories
from app.bank.served import served_bundle
from app.data.trajectory import TrajectorySet
from app.data.windows import make_windows, segment_features
from app.learning.checkpoint import load_model, mlp_numpy
from app.learning.config import load_train_config
from app.learning.fsq import quantize
from app.learning.train import ours_code_count, train_and_save
from app.settings import Settings, get_settings

TRAIN_TARGET_S = 60.0
INFERENCE_TARGET_RATIO = 3.0
STUDY = "paper_study"
TRAJECTORIES, SEED = 2000, 0  # what `make data` simulates


def best_per_call(fn, number: int = 2000, repeat: int = 7) -> float:
    """Fastest mean time per call over `repeat` runs (least disturbed by other processes)."""
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def bare_numpy_trial(model, x: np.ndarray, states_norm: np.ndarray):
    """The same weights with nothing around them: encoder, quantise/mean, decoder."""
    levels = np.asarray(model.levels or [], dtype=np.float32)

    def run():
        z = mlp_numpy(x, model.encoder_layers)[:, : model.latent_dim]
        if model.name == "ours":
            z = quantize(z, levels)
        return mlp_numpy(np.concatenate([np.repeat(z, len(states_norm), 0), states_norm], 1),
                         model.decoder_layers)
    return run


def torch_trial(model, x: np.ndarray, states_norm: np.ndarray):
    """The same trial through the torch network in inference_mode."""
    net = model.torch_module()
    xt, st = torch.from_numpy(x), torch.from_numpy(states_norm)

    def run():
        with torch.inference_mode():
            z = net.infer_latent(xt)
            return net.decode(z.expand(len(st), -1), st)
    return run


def time_trial(ckpt: Path, trajs: TrajectorySet) -> dict:
    """Per-call seconds of the API trial, the bare-numpy forward and torch."""
    model = load_model(ckpt)
    w = make_windows(trajs, model.segment_len, model.n_actions, per_trajectory=1)
    segment, states = w.segment_positions[0], w.positions[:5, model.segment_len]
    x = model.norm.features(segment_features(segment[None], model.dt_s))
    states_norm = model.norm.states(states)
    torch.set_num_threads(1)
    api = best_per_call(lambda: model.trial(segment, states))
    bare = best_per_call(bare_numpy_trial(model, x, states_norm))
    torch_s = best_per_call(torch_trial(model, x, states_norm), number=500)
    return {"api_us": api * 1e6, "bare_us": bare * 1e6, "torch_us": torch_s * 1e6}


def vae_clusters(settings: Settings, world: str, ours_checkpoint: Path | None) -> int:
    """The VAE's k-means k: the codes the Ours this run trained uses, else the served
    bundle's primary Ours."""
    if ours_checkpoint is not None:
        return ours_code_count(ours_checkpoint, world)
    bundle = served_bundle(settings, STUDY)
    return int(bundle.model(world, "ours", bundle.seeds[0]).codes["n_codes_used"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", nargs="+", default=["highway", "obstacle"])
    parser.add_argument("--models", nargs="+", default=["ours", "vae"])
    args = parser.parse_args()
    cfg = load_train_config()
    settings = get_settings()
    layout = settings.layout
    failed = False
    for world in args.worlds:
        ensure_trajectories(layout, world, TRAJECTORIES, SEED, print)
        trajs = TrajectorySet.load(layout.trajectories(world))
        ours_checkpoint = None  # until this run trains its own
        with tempfile.TemporaryDirectory() as tmp:
            for model_name in args.models:
                clusters = (vae_clusters(settings, world, ours_checkpoint)
                            if model_name == "vae" else None)
                started, cpu_started = time.perf_counter(), time.process_time()
                ckpt = train_and_save(trajs, model_name, 0, cfg, Path(tmp) / model_name,
                                      progress=False, vae_clusters=clusters)
                if model_name == "ours":
                    ours_checkpoint = ckpt
                wall = time.perf_counter() - started
                cpu = time.process_time() - cpu_started
                t = time_trial(ckpt, trajs)
                ratio = t["api_us"] / t["bare_us"]
                print(f"{world:9s} {model_name:5s} train {wall:6.1f} s wall ({cpu:5.1f} s CPU) on "
                      f"{len(trajs)} trajectories (target < {TRAIN_TARGET_S:.0f} s, ratio "
                      f"{wall / TRAIN_TARGET_S:.2f}; load average {os.getloadavg()[0]:.1f}) | "
                      f"trial {t['api_us']:6.1f} us vs bare numpy {t['bare_us']:5.1f} us = "
                      f"{ratio:.2f}x (target <= {INFERENCE_TARGET_RATIO:.0f}x); "
                      f"torch {t['torch_us']:6.1f} us = {t['torch_us'] / t['bare_us']:.2f}x")
                failed |= wall >= TRAIN_TARGET_S or ratio > INFERENCE_TARGET_RATIO
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
