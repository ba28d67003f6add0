"""Two-agent trajectory containers and their reproducible .npz storage.

Shape legend: N trajectories, T = max steps, A = 2 agents (0 = robot, 1 = human), D = 2 (x, y).
- positions [N, T+1, A, D] m, in the world's frame (see Scene.frame)
- actions   [N, T, A, D]   m/s, always (positions[t+1] - positions[t]) / dt
- headings  [N, T+1, A]    rad, for drawing; speeds [N, T+1, A] m/s, world-frame speed
- lengths   [N]            number of valid actions; later steps repeat the last state
- labels    name -> [N] int, with class names in label_names
- held_out  [N] bool or None: recorded worlds mark the trajectories cut from held-out
            recordings, which every checkpoint keeps as its test split; None lets the trainer
            draw the split (simulated worlds)
- sizes     [N, A, 2] m (length, width) or None: a recorded world's vehicles as recorded;
            None: every agent has the scene's `agents` size (simulated worlds)
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.core.files import write_npz
from app.data.scene import Scene

ROBOT, HUMAN = 0, 1


def wrap_angle(angle) -> np.ndarray:
    """Angles [rad] wrapped into [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


@dataclass
class Episode:
    """One rollout before padding: positions [L+1, A, D], headings/speeds [L+1, A], labels."""

    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray
    labels: dict[str, int] = field(default_factory=dict)
    sizes: np.ndarray | None = None  # [A, 2] m (length, width) as recorded

    @property
    def length(self) -> int:
        """Number of actions (steps) in the episode."""
        return len(self.positions) - 1


@dataclass(frozen=True)
class Covered:
    """Robot states a trial's start states are drawn from: positions [M, 2] (m) and headings
    [M] (rad), every valid step of the trajectories the models learned from; speeds [M] (m/s)
    and next_moves [M, n, 2] (m/s, what the robot did over the n steps after the state, NaN
    past its trajectory's end) where a start may keep the state it was drawn from."""

    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray | None = None
    next_moves: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.positions)


class Rejected(Exception):
    """A rollout that must not enter the dataset; the message is the reason (e.g. 'collision')."""


@dataclass
class TrajectorySet:
    """A padded batch of episodes of one world, with labels and scene."""

    world: str
    dt_s: float
    positions: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray
    lengths: np.ndarray
    labels: dict[str, np.ndarray]
    label_names: dict[str, list[str]]
    scene: Scene
    held_out: np.ndarray | None = None
    sizes: np.ndarray | None = None

    @property
    def actions(self) -> np.ndarray:
        """Velocities [N, T, A, D] = position differences / dt (zero after the end)."""
        return (np.diff(self.positions, axis=1) / self.dt_s).astype(np.float32)

    def __len__(self) -> int:
        return len(self.lengths)

    def label_counts(self) -> dict[str, dict[str, int]]:
        """Trajectories per class of every named label (meta.json's `label_counts`)."""
        return {name: {cls: int((values == k).sum())
                       for k, cls in enumerate(self.label_names[name])}
                for name, values in self.labels.items() if name in self.label_names}

    @classmethod
    def from_episodes(cls, world: str, dt_s: float, episodes: list[Episode],
                      label_names: dict[str, list[str]], scene: Scene,
                      held_out: np.ndarray | None = None) -> "TrajectorySet":
        """Pad episodes to the longest one by repeating each final state."""
        horizon = max(ep.length for ep in episodes)

        def pad(arr: np.ndarray) -> np.ndarray:
            reps = horizon + 1 - len(arr)
            return np.concatenate([arr, np.repeat(arr[-1:], reps, axis=0)], axis=0)

        return cls(
            world=world,
            dt_s=dt_s,
            positions=np.stack([pad(ep.positions) for ep in episodes]).astype(np.float32),
            headings=np.stack([pad(ep.headings) for ep in episodes]).astype(np.float32),
            speeds=np.stack([pad(ep.speeds) for ep in episodes]).astype(np.float32),
            lengths=np.array([ep.length for ep in episodes], dtype=np.int32),
            labels={name: np.array([ep.labels[name] for ep in episodes], dtype=np.int32)
                    for name in sorted(episodes[0].labels)},
            label_names=label_names,
            scene=scene,
            held_out=None if held_out is None else np.asarray(held_out, dtype=bool),
            sizes=(np.stack([ep.sizes for ep in episodes]).astype(np.float32)
                   if all(ep.sizes is not None for ep in episodes) else None),
        )

    def scene_of(self, i: int) -> Scene:
        """The scene with its agents at trajectory i's recorded sizes (the scene itself
        when the trajectories carry none)."""
        if self.sizes is None:
            return self.scene
        agents = [a.model_copy(update={"length_m": float(size[0]), "width_m": float(size[1])})
                  for a, size in zip(self.scene.agents, self.sizes[i], strict=True)]
        return self.scene.model_copy(update={"agents": agents})

    def subset(self, index: np.ndarray) -> "TrajectorySet":
        """The trajectories at `index`, same world and scene."""
        return TrajectorySet(
            world=self.world, dt_s=self.dt_s, positions=self.positions[index],
            headings=self.headings[index], speeds=self.speeds[index],
            lengths=self.lengths[index],
            labels={k: v[index] for k, v in self.labels.items()},
            label_names=self.label_names, scene=self.scene,
            held_out=None if self.held_out is None else self.held_out[index],
            sizes=None if self.sizes is None else self.sizes[index],
        )

    def save(self, path: Path) -> None:
        """Write one self-contained .npz (atomic, byte-reproducible)."""
        header = {"world": self.world, "dt_s": self.dt_s, "label_names": self.label_names,
                  "scene": self.scene.model_dump()}
        arrays = {
            "positions": self.positions, "headings": self.headings, "speeds": self.speeds,
            "lengths": self.lengths,
            "header_json": np.frombuffer(json.dumps(header, sort_keys=True).encode(), np.uint8),
        }
        arrays.update({f"label__{k}": v for k, v in self.labels.items()})
        if self.held_out is not None:
            arrays["held_out"] = self.held_out.astype(bool)
        if self.sizes is not None:
            arrays["sizes"] = self.sizes
        write_npz(path, arrays)

    @classmethod
    def load(cls, path: Path) -> "TrajectorySet":
        """Read a file written by `save`."""
        with np.load(path, allow_pickle=False) as npz:
            header = json.loads(npz["header_json"].tobytes().decode())
            labels = {k.removeprefix("label__"): npz[k] for k in npz.files
                      if k.startswith("label__")}
            return cls(
                world=header["world"], dt_s=float(header["dt_s"]),
                positions=npz["positions"], headings=npz["headings"], speeds=npz["speeds"],
                lengths=npz["lengths"], labels=labels, label_names=header["label_names"],
                scene=Scene.model_validate(header["scene"]),
                held_out=npz["held_out"] if "held_out" in npz.files else None,
                sizes=npz["sizes"] if "sizes" in npz.files else None,
            )
