"""Shared pieces of both models: MLPs, the decoder objective and input normalisation.

Shape legend: B batch, T segment_len, n n_actions, d latent dim.
- x       [B, T*8] normalised encoder features (see app.data.windows)
- state   [B, 4]   normalised joint state (robot xy, human xy)
- actions [B, n*2] normalised robot velocities, step-major (vx0, vy0, vx1, ...)
"""

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn


def mlp(n_in: int, hidden: list[int], n_out: int) -> nn.Sequential:
    """Fully connected ReLU network; the last layer is linear."""
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(n_in, width), nn.ReLU()]
        n_in = width
    layers.append(nn.Linear(n_in, n_out))
    return nn.Sequential(*layers)


@dataclass
class Batch:
    """One minibatch of normalised tensors for the prediction and reconstruction losses."""

    x: torch.Tensor
    end_state: torch.Tensor
    pred_target: torch.Tensor
    recon_state: torch.Tensor
    recon_target: torch.Tensor


class LatentActionModel(nn.Module):
    """Encoder -> latent z; decoder (z, state) -> n robot actions. Subclasses define the latent."""

    def __init__(self, segment_len: int, n_actions: int, latent_dim: int,
                 encoder_hidden: list[int], decoder_hidden: list[int], encoder_out: int):
        super().__init__()
        self.segment_len, self.n_actions, self.latent_dim = segment_len, n_actions, latent_dim
        self.encoder = mlp(segment_len * 8, encoder_hidden, encoder_out)
        self.decoder = mlp(latent_dim + 4, decoder_hidden, n_actions * 2)

    def decode(self, z: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """Normalised robot actions [B, n*2] for latent z [B, d] and state [B, 4]."""
        return self.decoder(torch.cat([z, state], dim=-1))

    def latent(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(z used by the decoder, regulariser added to the loss)."""
        raise NotImplementedError

    def infer_latent(self, x: torch.Tensor) -> torch.Tensor:
        """The deterministic latent used at inference."""
        raise NotImplementedError

    def losses(self, batch: Batch, pred_weight: float, recon_weight: float) -> dict:
        """Weighted L_pred + L_recon (MSE) plus the model's regulariser; 'total' is optimised."""
        z, regulariser = self.latent(batch.x)
        pred = nn.functional.mse_loss(self.decode(z, batch.end_state), batch.pred_target)
        recon = nn.functional.mse_loss(self.decode(z, batch.recon_state), batch.recon_target)
        total = pred_weight * pred + recon_weight * recon + regulariser
        return {"total": total, "pred": pred, "recon": recon, "reg": regulariser}


@dataclass
class Normaliser:
    """Train-split statistics: encoder features (8 per step), states (4), robot actions (2)."""

    feat_mean: np.ndarray
    feat_std: np.ndarray
    act_mean: np.ndarray
    act_std: np.ndarray

    @classmethod
    def fit(cls, features: np.ndarray, robot_actions: np.ndarray,
            action_axis_weights=(1.0, 1.0)) -> "Normaliser":
        """Per-channel mean/std of features [.., 8] and robot actions [.., 2].

        An action axis weight w scales that axis' normalised MSE by w: its std is divided
        by sqrt(w), which leaves the un-normalised predictions exact."""
        feats = features.reshape(-1, 8).astype(np.float64)
        acts = robot_actions.reshape(-1, 2).astype(np.float64)
        act_std = _safe_std(acts) / np.sqrt(np.asarray(action_axis_weights, dtype=np.float32))
        return cls(feats.mean(0).astype(np.float32), _safe_std(feats),
                   acts.mean(0).astype(np.float32), act_std.astype(np.float32))

    def features(self, feats: np.ndarray) -> np.ndarray:
        """Normalise features [.., T, 8] and flatten to [.., T*8]."""
        out = (feats - self.feat_mean) / self.feat_std
        return out.reshape(*feats.shape[:-2], -1).astype(np.float32)

    def states(self, states: np.ndarray) -> np.ndarray:
        """Normalise joint states [.., 2, 2] to [.., 4] with the features' position stats."""
        flat = states.reshape(*states.shape[:-2], 4)
        return ((flat - self.feat_mean[:4]) / self.feat_std[:4]).astype(np.float32)

    def actions(self, actions: np.ndarray) -> np.ndarray:
        """Normalise robot actions [.., n, 2] to [.., n*2]."""
        out = (actions - self.act_mean) / self.act_std
        return out.reshape(*actions.shape[:-2], -1).astype(np.float32)

    def unnormalise_actions(self, flat: np.ndarray, n_actions: int) -> np.ndarray:
        """Normalised [.., n*2] back to m/s [.., n, 2]."""
        out = flat.reshape(*flat.shape[:-1], n_actions, 2) * self.act_std + self.act_mean
        return out.astype(np.float32)

    def to_dict(self) -> dict:
        """Plain float lists for the checkpoint."""
        return {k: [float(v) for v in getattr(self, k)]
                for k in ("feat_mean", "feat_std", "act_mean", "act_std")}

    @classmethod
    def from_dict(cls, data: dict) -> "Normaliser":
        """Inverse of `to_dict`."""
        return cls(**{k: np.asarray(data[k], dtype=np.float32)
                      for k in ("feat_mean", "feat_std", "act_mean", "act_std")})


def _safe_std(values: np.ndarray) -> np.ndarray:
    # a constant channel (e.g. a human who never moves sideways) must not divide by zero
    return np.maximum(values.std(0), 1e-3).astype(np.float32)
