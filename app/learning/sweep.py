"""A small documented sweep of FSQ levels, segment length and loss weights for one world.

Run: .venv/bin/python -m app.learning.sweep --world highway [--out var/models/sweep]
Trains Ours (seed 0) once per setting on var/data/<world>/trajectories.npz and prints one
row per setting: codes used, perplexity, held-out purity / NMI against the robot's labels
(raw and derived; "majority" is the purity of putting every window in one cluster), MSE and
wall time. Rows are also appended to <out>/<world>/sweep.jsonl.
"""

import argparse
import json
import time
from pathlib import Path

from app.data.trajectory import TrajectorySet
from app.learning.config import load_train_config
from app.learning.train import train_model
from app.settings import get_settings

SETTINGS = [
    {"levels": [2, 2, 2]},
    {"levels": [3, 3]},
    {"levels": [3, 3, 3]},
    {"levels": [5, 5]},
    {"levels": [3, 3], "segment_len": 7},
    {"levels": [3, 3], "recon_weight": 2.0},
    {"levels": [3, 3], "action_axis_weights": [1.0, 4.0]},
]


def sweep_row(trajs: TrajectorySet, overrides: dict, out_dir: Path) -> dict:
    """Train one setting and summarise its held-out metrics."""
    started = time.perf_counter()
    ckpt = train_model(trajs, "ours", 0, load_train_config(overrides=overrides), out_dir,
                       progress=False)
    metrics = json.loads((ckpt.parent / "metrics.json").read_text())
    test = metrics["test"]
    return {"world": trajs.world, "settings": overrides,
            "wall_s": round(time.perf_counter() - started, 1),
            "epochs": metrics["epochs_run"], "codes_used": metrics["n_codes_used"],
            "perplexity": round(test["usage"]["perplexity"], 2),
            "agreement": {k: {m: round(v[m], 3) for m in ("purity", "nmi", "majority")}
                          for k, v in test["agreement"].items() if k.startswith("robot_")},
            "mse": round(test["prediction"]["mse"], 4),
            "mse_constant_velocity": round(test["constant_velocity"]["mse"], 4)}


def format_row(row: dict) -> str:
    """One line: settings, codes, and purity/NMI per robot label."""
    scores = "  ".join(f"{k} {v['purity']:.3f}/{v['nmi']:.3f} (maj {v['majority']:.3f})"
                       for k, v in row["agreement"].items())
    return (f"{json.dumps(row['settings']):55s} codes {row['codes_used']:2d} "
            f"ppl {row['perplexity']:5.2f} mse {row['mse']:.3f} | purity/NMI: {scores}")


def main() -> None:
    """Parse arguments and run every setting of the sweep."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", required=True)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    data_dir = get_settings().data_dir
    trajs = TrajectorySet.load(data_dir / "data" / args.world / "trajectories.npz")
    out = (args.out or data_dir / "models" / "sweep") / args.world
    for i, overrides in enumerate(SETTINGS):
        row = sweep_row(trajs, overrides, out / f"setting{i}")
        print(format_row(row), flush=True)
        with open(out / "sweep.jsonl", "a") as fh:
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
