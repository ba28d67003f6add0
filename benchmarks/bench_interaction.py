"""Time `tomstudy interaction` end to end on generated files, on one and on two processes.

Generates the default synthetic scenario (v1.2 layout) in a temporary folder, then times
(a) one Ours training on its train pairs (baseline) and (b) the whole command with
`--workers 1` (today's path: every training one after another in this process) and then
`--workers 2`, back to back on the same files: load and validate, the FSQ levels grid
(7 Ours trainings), 2 x 10 trainings, the human-relative frame row (2 x 5 trainings;
`--frame-seeds 0` leaves it out), scoring, tests, the supervised ceilings, figures, report.
For each run: wall time, CPU time (this process and its workers), wall time per track file
read and per seed (the seed phase over the primary and frame-row seeds), and the phases'
wall times; then the 1-to-2 ratio, whether the per-seed errors are identical, and whether
the 2-process command stays under the 2-minute target. CPU time is printed too because the
machine is shared: wall time depends on the load.

    .venv/bin/python benchmarks/bench_interaction.py [--scenario DR_USA_Roundabout_FT]
        [--layout v1.2] [--frame-seeds N]
"""

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

from app.interaction.config import InteractionConfig
from app.interaction.dataset import load_scenario_data
from app.interaction.experiment import experiment_train_config, run_command
from app.layout import Layout
from app.learning.config import load_train_config
from app.learning.train import train_and_save
from app.recordings.synthetic_tracks import generate

TARGET_S = 120.0
WORKERS = (1, 2)


def cpu_s() -> float:
    """CPU seconds of this process and of its finished child processes (the workers)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def timed_command(root: Path, scenario: str, frame_seeds: int | None, workers: int) -> dict:
    """One `tomstudy interaction` run into its own var/ folder: summary, meta, wall and CPU."""
    layout = Layout(root / f"var_workers_{workers}")
    wall, cpu = time.perf_counter(), cpu_s()
    summary = run_command(root / "data", scenario, layout, frame_seeds=frame_seeds,
                          workers=workers)
    wall, cpu = time.perf_counter() - wall, cpu_s() - cpu
    meta = json.loads((layout.interaction_report(scenario) / "meta.json").read_text())
    return {"summary": summary, "meta": meta, "wall": wall, "cpu": cpu}


def seed_jobs(summary: dict) -> int:
    """Primary seeds plus the frame row's: the jobs of the seed phase."""
    row = summary.get("sensitivity", {}).get("human_relative_frame")
    return summary["seeds"] + (row["seeds"] if row else 0)


def print_run(workers: int, run: dict, track_files: int) -> None:
    """One run's line: totals, per track file, per seed, phases."""
    phases = run["meta"]["phase_wall_time_s"]
    per_seed = phases["seeds"] / seed_jobs(run["summary"])
    print(f"--workers {workers}: {run['wall']:.1f} s wall, {run['cpu']:.1f} s CPU; "
          f"{run['wall'] / track_files:.1f} s wall per track file, {per_seed:.1f} s per seed; "
          f"phases (s): " + ", ".join(f"{k} {v:.1f}" for k, v in phases.items()))


def per_seed_errors(summary: dict) -> list[float]:
    """Every per-seed alignment error of the primary and the frame row, in one list."""
    rows = [summary["paper_protocol"], *summary.get("sensitivity", {}).values()]
    return [e for row in rows for m in ("ours", "vae") for e in row["per_seed_alignment_error"][m]]


def main() -> None:
    """Generate, time the baseline training and the command on 1 and 2 processes, compare."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="DR_USA_Roundabout_FT")
    parser.add_argument("--layout", default="v1.2", choices=["v1.0", "v1.2"])
    parser.add_argument("--frame-seeds", type=int, default=None,
                        help="seeds of the human-relative frame row (default: the config's)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        generate(root / "data", args.scenario, args.layout)
        cfg = InteractionConfig()
        exp = load_scenario_data(root / "data", args.scenario, cfg)
        track_files = sum(Path(p).suffix == ".csv" for p in exp.inputs)
        train_cfg = experiment_train_config(load_train_config(), cfg)
        wall, cpu = time.perf_counter(), cpu_s()
        train_and_save(exp.train.trajs, "ours", 0, train_cfg, root / "baseline", progress=False)
        base_wall, base_cpu = time.perf_counter() - wall, cpu_s() - cpu
        runs = {w: timed_command(root, args.scenario, args.frame_seeds, w) for w in WORKERS}
    summary = runs[1]["summary"]
    print(f"pairs: {summary['pairs']}, track files: {track_files}, seeds: {summary['seeds']}, "
          f"seed jobs (with the frame row): {seed_jobs(summary)}")
    print(f"baseline, one Ours training: {base_wall:.1f} s wall, {base_cpu:.1f} s CPU")
    for workers, run in runs.items():
        print_run(workers, run, track_files)
    one, two = runs[1], runs[2]
    print(f"ratio --workers 1 / --workers 2: {one['wall'] / two['wall']:.2f} (wall), "
          f"{one['cpu'] / two['cpu']:.2f} (CPU); full / one training: "
          f"{two['wall'] / base_wall:.1f} (wall, 2 workers)")
    errors = [per_seed_errors(r["summary"]) for r in (one, two)]
    gap = max(abs(a - b) for a, b in zip(*errors, strict=True))
    print(f"per-seed alignment errors ({len(errors[0])}): "
          f"{'identical' if errors[0] == errors[1] else f'differ by at most {gap:.3g}'}")
    verdict = "met" if two["wall"] < TARGET_S else "MISSED"
    print(f"target: whole command (2 workers) under {TARGET_S:.0f} s wall: {verdict}")


if __name__ == "__main__":
    main()
