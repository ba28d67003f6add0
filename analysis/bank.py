"""The trial bank as the analysis reads it: each world's scene and every seed's answers.

A bank is JSON; a bundle stores it gzipped (`bank.json.gz`). Its SHA-256 is of the JSON
bytes, which is what each export row carries as `bank_sha256`. Per trial,
`predictions[model]` lists one answer per seed of the model's family, the primary seed
first; a bank built before model families stores one answer (a dict), read here as a
family of one.

Shape legend: K start states, n steps; an answer's `actions` is [K, n, 2] (m/s).
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.stats import PAIR
from app.core.files import read_bytes, sha256_bytes

ANSWER_KEYS = ["world", "trial_id", "start_index", "step"]


@dataclass(frozen=True)
class Bank:
    """A loaded trial bank and the SHA-256 of its JSON bytes."""

    data: dict
    sha256: str

    def scenes(self) -> dict:
        """Each world's scene (JSON), for the field figures."""
        return {world: entry["scene"] for world, entry in self.data["worlds"].items()}


def read_bank(path: Path) -> Bank | None:
    """The bank at `path` (gunzipped if it ends in .gz), or None if there is no file."""
    path = Path(path)
    if not path.is_file():
        return None
    raw = read_bytes(path)
    return Bank(json.loads(raw), sha256_bytes(raw))


def family(answers: list | dict) -> list[dict]:
    """A trial's answers of one model as a list, primary seed first (an old bank's one)."""
    return answers if isinstance(answers, list) else [answers]


def seed_answers(bank: dict, models: tuple[str, ...] = PAIR) -> pd.DataFrame:
    """One row per (world, trial, start state, step, model, seed): the seed's action.

    `seed_index` is the answer's place in the family (0 = the primary seed, whose actions
    the export's `<model>_vx/_vy` columns carry); `seed` is the training seed."""
    parts: dict[str, list] = {c: [] for c in (*ANSWER_KEYS, "model", "seed_index", "seed",
                                              "content_hash", "vx", "vy")}
    for world, world_bank in bank["worlds"].items():
        for trial in world_bank["trials"]:
            for model in models:
                for index, answer in enumerate(family(trial["predictions"][model])):
                    actions = np.asarray(answer["actions"], dtype=np.float64)  # [K, n, 2]
                    k, n = actions.shape[:2]
                    labels = {"world": world, "trial_id": trial["trial_id"], "model": model,
                              "seed_index": index, "seed": answer.get("seed", index),
                              "content_hash": answer["content_hash"]}
                    for col, value in labels.items():
                        parts[col].append(np.full(k * n, value, dtype=object))
                    parts["start_index"].append(np.repeat(np.arange(k), n))
                    parts["step"].append(np.tile(np.arange(n), k))
                    parts["vx"].append(actions[..., 0].ravel())
                    parts["vy"].append(actions[..., 1].ravel())
    frame = pd.DataFrame({c: np.concatenate(v) if v else [] for c, v in parts.items()})
    ints = ["start_index", "step", "seed_index", "seed"]
    return frame.astype({c: np.int64 for c in ints} | {c: str for c in (
        "world", "trial_id", "model", "content_hash")})


def family_hashes(bank: dict, models: tuple[str, ...] = PAIR) -> dict:
    """{world: {model: {seed (str): content_hash}}} of the answers the bank stores, in the
    shape of a bundle manifest's `models`, so the two can be compared."""
    out: dict = {}
    answers = seed_answers(bank, models).drop_duplicates(["world", "model", "seed"])
    for row in answers.itertuples(index=False):
        out.setdefault(row.world, {}).setdefault(row.model, {})[str(row.seed)] = row.content_hash
    return out
