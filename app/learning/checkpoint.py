"""Self-describing checkpoints and the numpy inference interface both models share.

A checkpoint is a plain dict (tensors, lists, numbers, strings) so that
`torch.load(path, weights_only=True)` reads it. It holds the weights, model args,
normalisation, data meta and hash, train config, per-code summaries and a content hash
(sha256 over everything else) that `load_model` verifies. The data meta leaves out how long
and on how many processes the data was simulated (RUN_ONLY_SOURCE_KEYS): they are not what
the data is, and the same data trained with the same seed must give the same content hash.
Checkpoints made before this carry them, and verify as they are (the hash is over what the
file holds).

Inference runs in numpy on the same weights (no torch call per request): one study
trial is a handful of small matrix products, where torch's per-call overhead dominates.
Ours quantises there with app.learning.fsq's functions, the ones training runs on tensors.
"""

import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.core.files import atomic_path, read_bytes
from app.data.windows import segment_features
from app.learning.fsq import codes_to_indices, indices_to_codes, mixed_radix_basis, quantize
from app.learning.networks import Normaliser

FORMAT = "tomstudy-model-v1"
REQUIRED_KEYS = ("format", "kind", "world", "dt_s", "model_args", "state_dict", "norm",
                 "data_meta", "data_hash", "train_config", "codes", "content_hash")
# keys of the data's meta.json that say how a simulation ran, not what it made (its
# content_sha256 says that): left out of a checkpoint's data meta, so of its content hash
RUN_ONLY_SOURCE_KEYS = ("wall_time_s", "workers")


class CheckpointError(Exception):
    """A checkpoint is missing, corrupt, or does not match what it is used with."""


def content_hash(payload: dict) -> str:
    """sha256 hex of the checkpoint's content: every key except 'content_hash' itself."""
    import torch

    digest = hashlib.sha256()
    plain = {k: v for k, v in payload.items() if k not in ("state_dict", "content_hash")}
    digest.update(json.dumps(plain, sort_keys=True).encode())
    for name in sorted(payload["state_dict"]):
        tensor = payload["state_dict"][name].detach().cpu().contiguous()
        digest.update(f"{name}|{tensor.dtype}|{tuple(tensor.shape)}".encode())
        digest.update(tensor.to(torch.float64).numpy().tobytes())
    return digest.hexdigest()


def save_checkpoint(path: Path, payload: dict) -> str:
    """Add the content hash, write atomically, return the hash."""
    import torch

    payload = dict(payload, format=FORMAT)
    payload["content_hash"] = content_hash(payload)
    with atomic_path(Path(path)) as tmp:
        torch.save(payload, tmp)
    return payload["content_hash"]


def _numpy_layers(state_dict: dict, prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
    indices = sorted({int(k.split(".")[1]) for k in state_dict if k.startswith(prefix + ".")})
    return [(state_dict[f"{prefix}.{i}.weight"].numpy().T.copy(),
             state_dict[f"{prefix}.{i}.bias"].numpy().copy()) for i in indices]


def mlp_numpy(x: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """ReLU MLP forward in numpy; the last layer is linear."""
    for weight, bias in layers[:-1]:
        x = np.maximum(x @ weight + bias, 0.0)
    weight, bias = layers[-1]
    return x @ weight + bias


@dataclass
class TrainedModel:
    """A loaded checkpoint: numpy in, numpy out, for the study server, fields and metrics."""

    name: str
    world: str
    segment_len: int
    n_actions: int
    dt_s: float
    content_hash: str
    latent_dim: int
    levels: list[int] | None
    norm: Normaliser
    encoder_layers: list
    decoder_layers: list
    kmeans_centres: np.ndarray | None
    codes: dict
    data_hash: str
    data_meta: dict
    train_config: dict
    model_args: dict
    path: Path | None = None
    _state_dict: dict = field(default_factory=dict, repr=False)

    def same_weights(self, other: "TrainedModel") -> bool:
        """True when both checkpoints hold exactly the same parameters."""
        mine, theirs = self._state_dict, other._state_dict
        return mine.keys() == theirs.keys() and all(
            np.array_equal(np.asarray(mine[k]), np.asarray(theirs[k])) for k in mine)

    def __post_init__(self) -> None:
        # per-call constants of the study server's fast path, computed once
        if self.levels:  # Ours: the quantiser's level set and code-index place values
            self._levels_arr = np.asarray(self.levels, dtype=np.float32)
            self._basis = np.asarray(mixed_radix_basis(self.levels), dtype=np.int64)
        # the decoder's first layer split into its latent rows and its state rows, so that
        # one z is applied to K states without tiling it
        first_w, first_b = self.decoder_layers[0]
        self._dec_wz, self._dec_ws = first_w[: self.latent_dim], first_w[self.latent_dim:]
        self._dec_b = first_b
        self._state_mean = self.norm.feat_mean[:4]
        self._state_std = self.norm.feat_std[:4]

    def encode(self, segment_positions: np.ndarray) -> np.ndarray:
        """Latent z [d] of one segment [L+1, 2, 2] (L >= segment_len); only the latest
        segment_len steps (the last segment_len+1 positions) are used."""
        segment_positions = np.asarray(segment_positions, dtype=np.float32)
        need = self.segment_len + 1
        if segment_positions.ndim != 3 or segment_positions.shape[1:] != (2, 2) \
                or len(segment_positions) < need:
            raise ValueError(f"segment must have shape [L+1, 2, 2] with L >= {self.segment_len}, "
                             f"got {segment_positions.shape}")
        return self.encode_batch(segment_positions[None, -need:])[0]

    def encode_batch(self, segments: np.ndarray) -> np.ndarray:
        """Latents [B, d] of segments [B, segment_len+1, 2, 2]."""
        segments = np.asarray(segments, dtype=np.float32)
        expected = (self.segment_len + 1, 2, 2)
        if segments.ndim != 4 or segments.shape[1:] != expected:
            raise ValueError(f"segments must have shape [B, {expected[0]}, 2, 2], "
                             f"got {segments.shape}")
        x = self.norm.features(segment_features(segments, self.dt_s))
        out = mlp_numpy(x, self.encoder_layers)
        if self.name == "ours":
            return quantize(out, self._levels_arr)
        return out[:, : self.latent_dim].astype(np.float32)  # posterior mean

    def code_of(self, z: np.ndarray) -> int:
        """Ours: the FSQ code index of z; VAE: the nearest stored k-means centre."""
        return int(self.codes_of(np.asarray(z, dtype=np.float32)[None])[0])

    def codes_of(self, z: np.ndarray) -> np.ndarray:
        """Vectorised `code_of` for latents [B, d]."""
        if self.name == "ours":
            return codes_to_indices(z, self._levels_arr, self._basis)
        dists = ((z[:, None, :] - self.kmeans_centres[None]) ** 2).sum(-1)
        return dists.argmin(axis=1)

    def latent_of_code(self, code: int) -> np.ndarray:
        """The latent vector a code stands for (FSQ code vector or k-means centre)."""
        if self.name == "ours":
            return indices_to_codes(np.array([code]), self._levels_arr, self._basis)[0]
        return self.kmeans_centres[code].astype(np.float32)

    def predict(self, z: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Robot velocities [K, n, 2] (m/s) for one latent z [d] and joint states [K, 2, 2]."""
        states = np.asarray(states, dtype=np.float32)
        if states.ndim != 3 or states.shape[1:] != (2, 2):
            raise ValueError(f"states must have shape [K, 2, 2], got {states.shape}")
        return self.predict_batch(np.asarray(z, dtype=np.float32)[None], states)

    def predict_batch(self, z: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Robot velocities [B, n, 2] for latents [B, d] (or [1, d]) and states [B, 2, 2]."""
        s = (states.reshape(len(states), 4) - self._state_mean) / self._state_std
        hidden = s @ self._dec_ws + (z @ self._dec_wz + self._dec_b)
        if len(self.decoder_layers) > 1:
            hidden = mlp_numpy(np.maximum(hidden, 0.0), self.decoder_layers[1:])
        return self.norm.unnormalise_actions(hidden, self.n_actions)

    def trial(self, segment_positions: np.ndarray, states: np.ndarray) -> tuple:
        """The study server's fast path: (z, code, actions [K, n, 2]) for one trial."""
        z = self.encode(segment_positions)
        return z, self.code_of(z), self.predict(z, states)

    def torch_module(self):
        """The torch network with these weights (for tests and further training)."""
        from app.learning.models import build_model

        module = build_model(self.name, self.model_args)
        module.load_state_dict(self._state_dict)
        return module.eval()


def load_model(path: Path, world: str | None = None) -> TrainedModel:
    """Read and verify a checkpoint; CheckpointError if corrupt, altered or for another world."""
    payload = _read_payload(Path(path))
    model = model_from_payload(payload, Path(path))
    if world is not None and model.world != world:
        raise CheckpointError(f"{path}: checkpoint is for world {model.world!r}, not {world!r}")
    return model


def check_matches_data(model: TrainedModel, world: str, dt_s: float,
                       data_hash: str | None = None) -> None:
    """Raise CheckpointError if the model was trained for another world, dt or dataset."""
    if model.world != world or abs(model.dt_s - dt_s) > 1e-9:
        raise CheckpointError(f"checkpoint is for {model.world} at dt={model.dt_s} s, "
                              f"data is {world} at dt={dt_s} s")
    if data_hash is not None and data_hash != model.data_hash:
        raise CheckpointError("checkpoint was trained on a different trajectory file "
                              f"(data hash {model.data_hash[:12]} vs {data_hash[:12]})")


def _read_payload(path: Path) -> dict:
    import torch

    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint file not found")
    try:  # a bundle's checkpoints are gzipped (app/bank/bundle.py)
        source = io.BytesIO(read_bytes(path)) if path.suffix == ".gz" else path
        payload = torch.load(source, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for a damaged file
        raise CheckpointError(f"{path}: not a readable checkpoint "
                              f"({type(err).__name__}: {str(err).splitlines()[0][:120]})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a {FORMAT} checkpoint")
    missing = [k for k in REQUIRED_KEYS if k not in payload]
    if missing:
        raise CheckpointError(f"{path}: checkpoint lacks {', '.join(missing)}")
    if content_hash(payload) != payload["content_hash"]:
        raise CheckpointError(f"{path}: content hash mismatch; the file was altered or damaged")
    return payload


def model_from_payload(payload: dict, path: Path | None = None) -> TrainedModel:
    """Build the numpy model from a checkpoint dict (already verified, or just made)."""
    args = payload["model_args"]
    state = payload["state_dict"]
    try:
        model = TrainedModel(
            name=payload["kind"], world=payload["world"], segment_len=int(args["segment_len"]),
            n_actions=int(args["n_actions"]), dt_s=float(payload["dt_s"]),
            content_hash=payload.get("content_hash", ""), latent_dim=int(args["latent_dim"]),
            levels=list(args["levels"]) if payload["kind"] == "ours" else None,
            norm=Normaliser.from_dict(payload["norm"]),
            encoder_layers=_numpy_layers(state, "encoder"),
            decoder_layers=_numpy_layers(state, "decoder"),
            kmeans_centres=(np.asarray(payload["kmeans_centres"], dtype=np.float32)
                            if payload["kind"] == "vae" else None),
            codes=payload["codes"], data_hash=payload["data_hash"],
            data_meta=payload["data_meta"], train_config=payload["train_config"],
            model_args=args, path=path, _state_dict=state,
        )
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: checkpoint content is inconsistent ({err!r})") from None
    if model.name not in ("ours", "vae"):
        raise CheckpointError(f"{path}: unknown model kind {model.name!r}")
    expected_in = model.segment_len * 8
    if model.encoder_layers[0][0].shape[0] != expected_in:
        raise CheckpointError(f"{path}: encoder weights do not match segment_len")
    # model_args["latent_dim"] is the VAE's own latent size (vae_latent_dim), not len(levels)
    if model.decoder_layers[0][0].shape[0] != model.latent_dim + 4:
        raise CheckpointError(f"{path}: decoder weights take a latent of size "
                              f"{model.decoder_layers[0][0].shape[0] - 4}, model_args say "
                              f"latent_dim {model.latent_dim}")
    return model
