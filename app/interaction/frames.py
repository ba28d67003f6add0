"""The frame of the models' positions: the map's (`absolute`) or the human car's.

`human_relative` is "from the other car's point of view": every position of a window, the
robot's and the human's, minus the human car's position at the window's last observed step
s^T, the moment the robot's next action is predicted. It translates and does not rotate
(the README says why). Actions are differences of positions, so velocities -- the
encoder's velocity inputs, the predicted and the true next actions, constant velocity --
are the same in both frames: only the positions the models see change.

Training in this frame needs the trainer's windows (split by pair) moved window by window,
so `train_in_frame` runs the trainer's own steps on moved windows.
"""

from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np

from app.data.trajectory import HUMAN
from app.data.windows import Windows
from app.learning.config import TrainConfig

Frame = Literal["absolute", "human_relative"]
FRAMES: tuple[Frame, ...] = ("absolute", "human_relative")


def human_origin(positions: np.ndarray, anchor_step: int) -> np.ndarray:
    """The human car's position [W, 2] at `anchor_step` of windows [W, S, A, 2]."""
    return np.asarray(positions, dtype=np.float64)[:, anchor_step, HUMAN]


def to_human_relative(positions: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Positions [W, S, A, 2] minus each window's origin [W, 2] (float64)."""
    return np.asarray(positions, dtype=np.float64) - origin[:, None, None, :]


def from_human_relative(relative: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The inverse of `to_human_relative`: back to map positions (float64)."""
    return np.asarray(relative, dtype=np.float64) + origin[:, None, None, :]


def in_frame(windows: Windows, frame: Frame) -> Windows:
    """The windows with positions in `frame` (the same object for `absolute`)."""
    if frame == "absolute":
        return windows
    if frame != "human_relative":
        raise ValueError(f"unknown frame {frame!r}; choose one of {', '.join(FRAMES)}")
    origin = human_origin(windows.positions, windows.segment_len)
    moved = to_human_relative(windows.positions, origin).astype(np.float32)
    return replace(windows, positions=moved)


def train_in_frame(trajs, kind: str, seed: int, cfg: TrainConfig, out_dir: Path, frame: Frame,
                   data_meta: dict, vae_clusters: int | None = None) -> Path:
    """Train Ours or the VAE with its windows in `frame`; the checkpoint's path.

    `absolute` is `train_and_save` itself. Otherwise the same steps on the same split and
    windows, each moved into the frame: normaliser, fit, the VAE's k-means, checkpoint
    (no metrics.json or loss plot)."""
    import torch

    from app.layout import CHECKPOINT_FILE
    from app.learning.checkpoint import save_checkpoint
    from app.learning.train import (
        Prepared,
        build_payload,
        fit_network,
        fit_normaliser,
        kmeans_centres,
        one_thread,
        prepare_windows,
        split_tensors,
        train_and_save,
    )

    if frame == "absolute":
        return train_and_save(trajs, kind, seed, cfg, out_dir, data_meta=data_meta,
                              progress=False, vae_clusters=vae_clusters)
    cfg = cfg.for_world(trajs.world)
    with one_thread():
        windows = {k: in_frame(w, frame) for k, w in prepare_windows(trajs, cfg).items()}
        norm = fit_normaliser(windows["train"], cfg)
        data = Prepared(windows, norm, split_tensors(windows["train"], norm),
                        split_tensors(windows["val"], norm))
        model, args, _ = fit_network(kind, seed, cfg, data, progress=False)
        centres = None
        if kind == "vae":
            with torch.no_grad():
                latents = model.infer_latent(data.val.x).numpy()
            centres = kmeans_centres(latents, vae_clusters, seed)
        payload = build_payload(trajs, kind, seed, cfg, model, args, data, centres,
                                {**data_meta, "frame": frame})
    path = Path(out_dir) / CHECKPOINT_FILE
    save_checkpoint(path, payload)
    return path
