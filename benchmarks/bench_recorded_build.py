"""Time `tomstudy bundle build` of the recorded-world study on generated files, on one and on
two processes.

Generates the interaction study's two scenarios (GENERATED, NOT REAL: a v1.2 roundabout and
a v1.0 intersection), then builds the study's bundle twice, each into its own data dir:
`--workers 1` (every selection cell and every checkpoint trained one after another in this
process: the path before this benchmark's issue) and `--workers 2`. Each build imports both
worlds' recordings, runs the model selection grid on each (15 cells), trains every seed of
Ours and the VAE, builds the bank and freezes it. Prints per build the wall and CPU time,
wall time per recording file read, per selection cell and per checkpoint, and the phases;
then the 1-to-2 ratios and whether both builds made the same bank and the same checkpoints
(they must: every job trains on one thread from its seed). A single Ours training on the
roundabout's data is timed first as the unit the ratios can be read against.

    .venv/bin/python benchmarks/bench_recorded_build.py [--seconds 900] [--seeds N]
        [--max-epochs N]

The defaults are the study's own build: generate-recordings' 900 s, the study's 5 seeds,
training.yaml's epochs. Small builds (a few hundred seconds of traffic, few epochs) gain
nothing from a second process: starting it (torch's import) costs what the jobs save.
"""

import argparse
import json
import resource
import shutil
import tempfile
import time
from pathlib import Path

import yaml

from app.bank.prepare import build_bundle
from app.learning.config import MODELS, load_train_config
from app.learning.select import grid_cells, load_selection_config
from app.learning.train import train_world
from app.recordings.generated import generate_study_recordings
from app.settings import REPO_ROOT, Settings

STUDY = "interaction_study"
WORKERS = (1, 2)


def cpu_s() -> float:
    """CPU seconds of this process and of its finished child processes (the workers)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def configs(root: Path, seeds: int | None, max_epochs: int | None) -> Path:
    """study_configs without the shipped bundles; the study's family cut to `seeds` seeds and
    training capped at `max_epochs` where given."""
    out = root / "configs"
    shutil.copytree(REPO_ROOT / "study_configs", out, ignore=shutil.ignore_patterns("bundles"))
    if seeds is not None:
        study = yaml.safe_load((out / f"{STUDY}.yaml").read_text())
        study["models"] = {"seeds": list(range(seeds))}
        (out / f"{STUDY}.yaml").write_text(yaml.safe_dump(study))
    if max_epochs is not None:
        training = yaml.safe_load((out / "training.yaml").read_text())
        training["max_epochs"] = max_epochs
        (out / "training.yaml").write_text(yaml.safe_dump(training))
    return out


def timed_build(root: Path, configs_dir: Path, workers: int) -> dict:
    """One bundle build into its own data dir: its manifest, wall and CPU time."""
    settings = Settings(data_dir=root / f"var_workers_{workers}", configs_dir=configs_dir,
                        recordings_dir=root / "recordings")
    wall, cpu = time.perf_counter(), cpu_s()
    bundle = build_bundle(settings, STUDY, workers, say=lambda line: None)
    return {"manifest": bundle.manifest, "wall": time.perf_counter() - wall,
            "cpu": cpu_s() - cpu}


def unit_training(root: Path, configs_dir: Path) -> float:
    """Wall time of one Ours training on the roundabout (the first build's data)."""
    settings = Settings(data_dir=root / "var_workers_1", configs_dir=configs_dir)
    started = time.perf_counter()
    train_world(settings.layout, "roundabout", "ours", 0,
                load_train_config(configs_dir / "training.yaml"), root / "unit", progress=False)
    return time.perf_counter() - started


def print_build(workers: int, run: dict, files: int, cells: int, checkpoints: int) -> None:
    """One build's line: totals, per recording file, per cell, per checkpoint, phases."""
    phases = run["manifest"]["built"]["phase_wall_time_s"]
    print(f"--workers {workers}: {run['wall']:.1f} s wall, {run['cpu']:.1f} s CPU; "
          f"{phases['data'] / files:.2f} s per recording file, "
          f"{phases['selection'] / cells:.1f} s per selection cell, "
          f"{phases['training'] / checkpoints:.1f} s per checkpoint; phases (s): "
          + ", ".join(f"{k} {v:.1f}" for k, v in phases.items()))


def main() -> None:
    """Generate, build on 1 and 2 processes, compare."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=900.0,
                        help="generated training traffic per scenario (half as much held out)")
    parser.add_argument("--seeds", type=int, default=None, help="default: the study's")
    parser.add_argument("--max-epochs", type=int, default=None, help="default: training.yaml's")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        generate_study_recordings(root / "recordings" / "INTERACTION", args.seconds)
        files = sum(1 for p in (root / "recordings").rglob("*.csv")
                    if "generator_labels" not in p.parts)
        configs_dir = configs(root, args.seeds, args.max_epochs)
        runs = {w: timed_build(root, configs_dir, w) for w in WORKERS}
        unit = unit_training(root, configs_dir)
    worlds = yaml.safe_load((configs_dir / f"{STUDY}.yaml").read_text())["worlds"]
    cells = len(worlds) * len(grid_cells(load_selection_config(
        configs_dir / "model_selection.yaml")))
    seeds = len(runs[1]["manifest"]["seeds"])
    checkpoints = len(MODELS) * len(worlds) * seeds
    print(f"{files} recording files, {len(worlds)} worlds, {seeds} seeds, max epochs "
          f"{args.max_epochs or 'as training.yaml'}; one Ours training on the roundabout: "
          f"{unit:.1f} s")
    for workers, run in runs.items():
        print_build(workers, run, files, cells, checkpoints)
    one, two = (runs[w]["manifest"] for w in WORKERS)
    print(f"ratio 1 -> 2 processes: {runs[1]['wall'] / runs[2]['wall']:.2f}x wall; phases: "
          + ", ".join(f"{k} {one['built']['phase_wall_time_s'][k] / max(v, 1e-9):.2f}x"
                      for k, v in two["built"]["phase_wall_time_s"].items()))
    same_bank = one["bank_sha256"] == two["bank_sha256"]
    same_models = json.dumps(one["models"], sort_keys=True) == json.dumps(two["models"],
                                                                          sort_keys=True)
    print(f"same bank: {same_bank}; same checkpoints (content hashes): {same_models}")
    if not (same_bank and same_models):
        raise SystemExit("the builds differ: a job's result depends on the process count")


if __name__ == "__main__":
    main()
