"""A small documented sweep of FSQ levels, segment length and loss weights for one world.

Run: tomstudy sweep --world highway [--out DIR]  (default out: var/models/sweep)
Trains Ours (seed 0) once per setting on var/data/<world>/trajectories.npz and prints one
row per setting: codes used, perplexity, held-out purity / NMI against the robot's labels
(raw and derived; "majority" is the purity of putting every window in one cluster), MSE and
wall time. Rows are also appended to <out>/<world>/sweep.jsonl.

Exploratory only: it reports label metrics on the test split, so it must not choose a
default. Defaults are chosen on validation data by `tomstudy select`. A row is
training.yaml plus the keys it names; training.yaml's per-world `selected:` values are ignored.

--ceiling instead prints, per robot label, the test accuracy of a supervised classifier
(gradient-boosted trees) on the same segment features: an estimate of how well *any*
function of the segment, hence any clustering's purity, can match that label.
"""

import json
import time
from collections.abc import Callable
from pathlib import Path

from app.data.trajectory import TrajectorySet
from app.layout import Layout
from app.learning.config import load_train_config
from app.learning.train import simulated_trajectories, train_and_save

SETTINGS = [
    {"levels": [2, 2, 2]},
    {"levels": [3, 3]},
    {"levels": [3, 3, 3]},
    {"levels": [5, 5]},
    {"levels": [3, 3], "segment_len": 7},
    {"levels": [3, 3], "recon_weight": 2.0},
    {"levels": [3, 3], "action_axis_weights": [1.0, 4.0]},
    {"levels": [3, 3], "fsq_noise_fraction": 0.0},  # straight-through rounding only
    {"levels": [3, 3], "fsq_noise_fraction": 1.0},
    {"levels": [5, 3]},
]


def sweep_row(trajs: TrajectorySet, overrides: dict, out_dir: Path) -> dict:
    """Train one setting and summarise its held-out metrics."""
    started = time.perf_counter()
    cfg = load_train_config(overrides={**overrides, "selected": {}})
    ckpt = train_and_save(trajs, "ours", 0, cfg, out_dir, progress=False)
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


def label_ceiling(trajs: TrajectorySet, overrides: dict | None = None) -> dict:
    """Held-out accuracy of a supervised segment -> label classifier, per robot label."""
    from sklearn.ensemble import HistGradientBoostingClassifier

    from app.data.windows import segment_features
    from app.learning.model_metrics import derived_labels
    from app.learning.train import prepare_windows

    windows = prepare_windows(trajs, load_train_config(overrides=overrides or {}))
    data = {}
    for split in ("train", "test"):
        w = windows[split]
        data[split] = (segment_features(w.segment_positions, w.dt_s).reshape(len(w), -1),
                       derived_labels(w, trajs.label_names))
    result = {}
    for name, train_labels in data["train"][1].items():
        if not name.startswith("robot_"):
            continue
        test_labels = data["test"][1][name]
        fit_rows, score_rows = train_labels >= 0, test_labels >= 0
        classifier = HistGradientBoostingClassifier(max_iter=200, random_state=0)
        classifier.fit(data["train"][0][fit_rows], train_labels[fit_rows])
        predicted = classifier.predict(data["test"][0][score_rows])
        result[name] = round(float((predicted == test_labels[score_rows]).mean()), 3)
    return result


def format_row(row: dict) -> str:
    """One line: settings, codes, and purity/NMI per robot label."""
    scores = "  ".join(f"{k} {v['purity']:.3f}/{v['nmi']:.3f} (maj {v['majority']:.3f})"
                       for k, v in row["agreement"].items())
    return (f"{json.dumps(row['settings']):55s} codes {row['codes_used']:2d} "
            f"ppl {row['perplexity']:5.2f} mse {row['mse']:.3f} | purity/NMI: {scores}")


def sweep_world(layout: Layout, world: str, out: Path | None = None, ceiling: bool = False,
                say: Callable[[str], None] = print) -> None:
    """`tomstudy sweep`: train every setting into out/<world>/setting<i>/ (default: the layout's
    sweep dir), say one line each and append it to sweep.jsonl; or only the label ceiling."""
    trajs = simulated_trajectories(layout, world)
    if ceiling:
        say(json.dumps({"world": world, "classifier_accuracy": label_ceiling(trajs)}))
        return
    out_dir = out / world if out else layout.sweep_dir(world)
    for i, overrides in enumerate(SETTINGS):
        row = sweep_row(trajs, overrides, out_dir / f"setting{i}")
        say(format_row(row))
        with open(out_dir / "sweep.jsonl", "a") as fh:
            fh.write(json.dumps(row) + "\n")
