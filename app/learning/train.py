"""Train Ours or the VAE on a TrajectorySet; write checkpoint.pt, metrics.json and loss.png.

`train_world` is the pipeline's train stage: `tomstudy train` and `serve --prepare` both run
it, so the same inputs give the same checkpoint whichever ran it.
"""

import json
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from app.core.files import atomic_path, trajectory_hash, write_json
from app.data.trajectory import ROBOT, TrajectorySet
from app.data.windows import Windows, make_windows, segment_features, split_by_trajectory
from app.layout import CHECKPOINT_FILE, Layout
from app.learning.checkpoint import (
    RUN_ONLY_SOURCE_KEYS,
    load_model,
    model_from_payload,
    save_checkpoint,
)
from app.learning.config import MODELS, TrainConfig
from app.learning.convergence import EarlyStopping, stopping_record
from app.learning.model_metrics import code_usage, derived_labels, evaluate
from app.learning.models import build_model, model_args
from app.learning.networks import Batch, LatentActionModel, Normaliser


@dataclass
class SplitTensors:
    """All normalised training tensors of one split; recon pairs for every t in 0..T-1."""

    x: torch.Tensor
    end_state: torch.Tensor
    pred_target: torch.Tensor
    recon_state: torch.Tensor
    recon_target: torch.Tensor

    def batch(self, rows: torch.Tensor, t: torch.Tensor) -> Batch:
        """Minibatch at `rows` with reconstruction step t per row."""
        return Batch(self.x[rows], self.end_state[rows], self.pred_target[rows],
                     self.recon_state[rows, t], self.recon_target[rows, t])


def split_tensors(windows: Windows, norm: Normaliser) -> SplitTensors:
    """Normalise a split's windows into tensors."""
    T = windows.segment_len
    pairs = [windows.recon_pair(np.full(len(windows), t)) for t in range(T)]
    return SplitTensors(
        x=torch.from_numpy(norm.features(segment_features(windows.segment_positions,
                                                          windows.dt_s))),
        end_state=torch.from_numpy(norm.states(windows.end_states)),
        pred_target=torch.from_numpy(norm.actions(windows.pred_targets)),
        recon_state=torch.from_numpy(np.stack([norm.states(s) for s, _ in pairs], axis=1)),
        recon_target=torch.from_numpy(np.stack([norm.actions(a) for _, a in pairs], axis=1)),
    )


def prepare_windows(trajs: TrajectorySet, cfg: TrainConfig) -> dict[str, Windows]:
    """Split by trajectory (cfg.split_seed) and cut windows per split."""
    split = split_by_trajectory(len(trajs), cfg.val_fraction, cfg.test_fraction, cfg.split_seed,
                                trajs.held_out)
    windows = {name: make_windows(trajs, cfg.segment_len, cfg.n_actions,
                                  cfg.windows_per_trajectory, index)
               for name, index in split.items()}
    for name, w in windows.items():
        if len(w) == 0:
            raise ValueError(f"{name} split has no windows: trajectories shorter than "
                             f"segment_len + n_actions = {cfg.segment_len + cfg.n_actions} steps?")
    return windows


def fit_normaliser(train: Windows, cfg: TrainConfig) -> Normaliser:
    """Train-split feature and robot-action statistics (action std scaled by axis weights)."""
    feats = segment_features(train.segment_positions, train.dt_s)
    return Normaliser.fit(feats, train.actions[:, :, ROBOT], cfg.action_axis_weights)


@dataclass
class Prepared:
    """One dataset's split windows, train-split normaliser and normalised train/val tensors."""

    windows: dict[str, Windows]
    norm: Normaliser
    train: SplitTensors
    val: SplitTensors


def prepare(trajs: TrajectorySet, cfg: TrainConfig,
            transform: Callable[[Windows], Windows] | None = None) -> Prepared:
    """Split, cut windows (each moved by `transform` if given, e.g. into another frame), fit
    the normaliser and build the train/val tensors."""
    windows = prepare_windows(trajs, cfg)
    if transform is not None:
        windows = {split: transform(w) for split, w in windows.items()}
    norm = fit_normaliser(windows["train"], cfg)
    return Prepared(windows, norm, split_tensors(windows["train"], norm),
                    split_tensors(windows["val"], norm))


@contextmanager
def one_thread():
    """Run torch on one thread: for these small MLPs a second thread costs more than it gives."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def fit_network(model_name: str, seed: int, cfg: TrainConfig, data: Prepared,
                progress: bool = True) -> tuple[LatentActionModel, dict, list[dict]]:
    """Seed torch, build `model_name` from cfg and fit it; returns (model in eval mode, args,
    history)."""
    torch.manual_seed(seed)
    args = model_args(cfg, model_name)
    model = build_model(model_name, args)
    return model, args, fit(model, data.train, data.val, cfg, seed, progress)


def _epoch(model, data: SplitTensors, cfg: TrainConfig, gen: torch.Generator,
           optimiser) -> float:
    model.train()
    order = torch.randperm(len(data.x), generator=gen)
    total, count = 0.0, 0
    for start in range(0, len(order), cfg.batch_size):
        rows = order[start:start + cfg.batch_size]
        t = torch.randint(0, cfg.segment_len, (len(rows),), generator=gen)
        loss = model.losses(data.batch(rows, t), cfg.pred_weight, cfg.recon_weight)["total"]
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        total, count = total + float(loss.detach()) * len(rows), count + len(rows)
    return total / count


@torch.no_grad()
def _validate(model, data: SplitTensors, cfg: TrainConfig, t: torch.Tensor) -> dict:
    model.eval()
    parts = model.losses(data.batch(torch.arange(len(data.x)), t), cfg.pred_weight,
                         cfg.recon_weight)
    return {k: float(v) for k, v in parts.items()}


def fit(model, train: SplitTensors, val: SplitTensors, cfg: TrainConfig, seed: int,
        progress: bool = True) -> list[dict]:
    """Adam until the validation loss converges (app/learning/convergence.py) or max_epochs;
    leaves the best epoch's weights in `model`."""
    gen = torch.Generator().manual_seed(seed)
    val_t = torch.randint(0, cfg.segment_len, (len(val.x),), generator=gen)
    # foreach: one update over all parameter tensors instead of a loop over them; the same
    # arithmetic, so the same weights bit for bit (torch's CPU default is the loop)
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.lr, foreach=True)
    history, best_state, stopping = [], None, EarlyStopping(cfg.patience_epochs)
    bar = tqdm(range(cfg.max_epochs), desc=f"train {type(model).__name__}", disable=not progress)
    for epoch in bar:
        train_loss = _epoch(model, train, cfg, gen, optimiser)
        scores = _validate(model, val, cfg, val_t)
        history.append({"epoch": epoch, "train_total": train_loss,
                        **{f"val_{k}": v for k, v in scores.items()}})
        bar.set_postfix(train=f"{train_loss:.4f}", val=f"{scores['total']:.4f}")
        if stopping.improved(epoch, scores["total"]):
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        elif stopping.done:
            break
    model.load_state_dict(best_state)
    model.eval()
    return history


def _latents(model, data: SplitTensors) -> np.ndarray:
    with torch.no_grad():
        return model.infer_latent(data.x).numpy()


def ours_code_count(ours_checkpoint: Path, world: str) -> int:
    """The VAE's k-means k: how many codes Ours uses on the same world (from its checkpoint)."""
    if not Path(ours_checkpoint).is_file():
        raise FileNotFoundError(f"{ours_checkpoint}: no Ours checkpoint. The VAE's k-means k is "
                                f"the number of codes Ours uses, so train Ours first (`tomstudy "
                                f"train --world {world} --model ours`, or pass --ours-checkpoint)")
    return int(load_model(ours_checkpoint, world=world).codes["n_codes_used"])


def kmeans_centres(latents: np.ndarray, k: int, seed: int) -> np.ndarray:
    """k-means centres [k, d] of validation latents, computed on one thread."""
    from sklearn.cluster import KMeans
    from threadpoolctl import threadpool_limits

    k = max(1, min(k, len(np.unique(latents.round(6), axis=0))))
    # scikit-learn adds up per-thread partial centres, so the centres' last bits (and at times
    # the clusters) follow the thread count: one thread gives the same VAE on any machine,
    # whether `tomstudy train` or a worker of a parallel run trains it
    with threadpool_limits(limits=1):
        return KMeans(n_clusters=k, n_init=10, random_state=seed).fit(latents).cluster_centers_


def code_summary(codes: np.ndarray, windows: Windows, label_names: dict,
                 min_share: float) -> dict:
    """Used codes with their share and majority label (validation windows), JSON-able."""
    usage = code_usage(codes, min_share)
    labels = derived_labels(windows, label_names)
    summary = []
    for code_str, count in sorted(usage["counts"].items(), key=lambda kv: -kv[1]):
        share = count / len(codes)
        if share < min_share:
            continue
        mask = codes == int(code_str)
        majority = {}
        for name, values in labels.items():
            classes = label_names.get(name) or label_names.get(_base_label(name, label_names))
            scored = values[mask & (values >= 0)]
            if len(scored) and classes:
                top = int(np.bincount(scored).argmax())
                majority[name] = {"label": classes[top],
                                  "fraction": float((scored == top).mean())}
        summary.append({"code": int(code_str), "share": float(share), "majority": majority})
    return {"used": summary, "n_codes_used": len(summary), "perplexity": usage["perplexity"]}


def _base_label(name: str, label_names: dict) -> str | None:
    """The raw label a derived one (e.g. robot_intent_in_progress) comes from."""
    return next((base for base in label_names if name.startswith(base + "_")), None)


def _plot_losses(history: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    epochs = [h["epoch"] for h in history]
    ax.plot(epochs, [h["train_total"] for h in history], label="train")
    ax.plot(epochs, [h["val_total"] for h in history], label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss (normalised MSE)")
    ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def train_and_save(trajs: TrajectorySet, model_name: str, seed: int, cfg: TrainConfig,
                   out_dir: Path, data_meta: dict | None = None, progress: bool = True,
                   vae_clusters: int | None = None,
                   transform: Callable[[Windows], Windows] | None = None) -> Path:
    """Train one model; write out_dir/checkpoint.pt, metrics.json, loss.png; return the .pt.

    cfg.selected[trajs.world] (the values model selection chose) is applied on top of cfg.
    The VAE needs `vae_clusters`, the k of its k-means (see `ours_code_count`). `transform`
    moves every window before training and testing (INTERACTION's frame sensitivity row)."""
    if model_name not in MODELS:
        raise ValueError(f"unknown model {model_name!r}; choose one of {', '.join(MODELS)}")
    if model_name == "vae" and vae_clusters is None:
        raise ValueError("training the VAE needs vae_clusters, the k of its k-means (the number "
                         "of codes Ours uses on the same data: ours_code_count)")
    started = time.perf_counter()
    cfg = cfg.for_world(trajs.world)
    with one_thread():
        data = prepare(trajs, cfg, transform)
        return _train(trajs, model_name, seed, cfg, Path(out_dir), data_meta, progress,
                      vae_clusters, started, data)


def build_payload(trajs: TrajectorySet, model_name: str, seed: int, cfg: TrainConfig,
                  model: LatentActionModel, args: dict, data: Prepared,
                  centres: np.ndarray | None = None, data_meta: dict | None = None) -> dict:
    """The checkpoint dict of a fitted network (codes summarised on validation windows)."""
    payload = {
        "kind": model_name, "world": trajs.world, "dt_s": float(trajs.dt_s), "model_args": args,
        "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
        "norm": data.norm.to_dict(), "data_meta": _data_meta(trajs, data.windows, data_meta),
        "data_hash": trajectory_hash(trajs),
        "train_config": cfg.model_dump(), "seed": seed,
        "kmeans_centres": centres.tolist() if centres is not None else None, "codes": {},
    }
    unsaved = model_from_payload(payload)
    val_codes = unsaved.codes_of(unsaved.encode_batch(data.windows["val"].segment_positions))
    payload["codes"] = code_summary(val_codes, data.windows["val"], trajs.label_names,
                                    cfg.min_code_share)
    return payload


def _train(trajs: TrajectorySet, model_name: str, seed: int, cfg: TrainConfig, out_dir: Path,
           data_meta: dict | None, progress: bool, vae_clusters: int | None,
           started: float, data: Prepared) -> Path:
    model, args, history = fit_network(model_name, seed, cfg, data, progress)
    train_seconds = time.perf_counter() - started

    centres = None
    if model_name == "vae":
        centres = kmeans_centres(_latents(model, data.val), vae_clusters, seed)
    payload = build_payload(trajs, model_name, seed, cfg, model, args, data, centres, data_meta)
    ckpt_path = out_dir / CHECKPOINT_FILE
    content = save_checkpoint(ckpt_path, payload)
    loaded = load_model(ckpt_path)
    windows = data.windows
    test = evaluate(loaded, windows["test"], trajs.label_names, cfg.min_code_share)
    metrics = {
        "kind": model_name, "world": trajs.world, "seed": seed, "content_hash": content,
        "train_wall_time_s": round(train_seconds, 2),
        **stopping_record(history, cfg.patience_epochs),
        "best_val": min(h["val_total"] for h in history), "history": history,
        "n_windows": {k: len(w) for k, w in windows.items()},
        "n_codes_used": payload["codes"]["n_codes_used"], "codes": payload["codes"],
        "test": test, "train_config": cfg.model_dump(),
    }
    write_json(out_dir / "metrics.json", metrics)
    _plot_losses(history, out_dir / "loss.png", f"{trajs.world} / {model_name} (seed {seed})")
    return ckpt_path


def _data_meta(trajs: TrajectorySet, windows: dict[str, Windows], extra: dict | None) -> dict:
    human_end = windows["train"].end_states[:, 1]
    meta = {
        "world": trajs.world, "dt_s": float(trajs.dt_s), "n_trajectories": len(trajs),
        "label_names": trajs.label_names, "scene": trajs.scene.model_dump(),
        "split_trajectories": {"test": sorted({int(i) for i in windows["test"].traj_index})},
        "human_end_median": [float(v) for v in np.median(human_end, axis=0)],
    }
    if extra:
        source = {k: v for k, v in extra.items() if k not in RUN_ONLY_SOURCE_KEYS}
        meta["source"] = json.loads(json.dumps(source, default=str))
    return meta


def simulated_trajectories(layout: Layout, world: str) -> TrajectorySet:
    """The world's simulated trajectories; FileNotFoundError says to simulate them first."""
    npz = layout.trajectories(world)
    if not npz.is_file():
        raise FileNotFoundError(f"{npz} not found; run `tomstudy simulate {world}` first")
    return TrajectorySet.load(npz)


def train_world(layout: Layout, world: str, model_name: str, seed: int, cfg: TrainConfig,
                out_dir: Path | None = None, ours_checkpoint: Path | None = None,
                progress: bool = True) -> Path:
    """The train stage: one model on the world's simulated trajectories, its meta.json stored as
    the checkpoint's data source (nothing that depends on where the data dir is).

    Writes into out_dir (default: the layout's model dir of this seed). The VAE's k-means k is
    read from `ours_checkpoint` (default: the layout's Ours checkpoint of the world and seed).
    FileNotFoundError names a missing input."""
    trajs = simulated_trajectories(layout, world)
    meta_path = layout.trajectories_meta(world)
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    clusters = None
    if model_name == "vae":
        clusters = ours_code_count(ours_checkpoint or layout.checkpoint(world, "ours", seed),
                                   world)
    out_dir = Path(out_dir) if out_dir else layout.model_dir(world, model_name, seed)
    return train_and_save(trajs, model_name, seed, cfg, out_dir, meta,
                          progress, clusters)
