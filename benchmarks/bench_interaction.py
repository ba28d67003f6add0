"""Time `tomstudy interaction` end to end on generated files against one model's training.

Generates the default synthetic scenario (v1.2 layout) in a temporary folder, then times
(a) one Ours training on its train pairs (baseline) and (b) the whole command: load and
validate, the FSQ levels grid (7 Ours trainings), 2 x 10 trainings, scoring, tests, the
human-relative frame row (2 x 5 trainings; `--frame-seeds 0` leaves it out), the
supervised ceilings, figures, report. Prints both wall times, the
CPU time, their ratio and whether the whole command stays under the 2-minute target.
CPU time is printed too because the machine is shared: wall time depends on the load.

    .venv/bin/python benchmarks/bench_interaction.py [--scenario DR_USA_Roundabout_FT]
        [--frame-seeds N]
"""

import argparse
import tempfile
import time
from pathlib import Path

from app.interaction.config import InteractionConfig
from app.interaction.dataset import load_scenario_data
from app.interaction.experiment import experiment_train_config, run_command
from app.interaction.synthetic import generate
from app.layout import Layout
from app.learning.config import load_train_config
from app.learning.train import train_and_save

TARGET_S = 120.0


def main() -> None:
    """Generate, time the baseline training and the full command, print the ratio."""
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
        train_cfg = experiment_train_config(load_train_config(), cfg)
        wall, cpu = time.perf_counter(), time.process_time()
        train_and_save(exp.train.trajs, "ours", 0, train_cfg, root / "baseline", progress=False)
        base_wall, base_cpu = time.perf_counter() - wall, time.process_time() - cpu
        wall, cpu = time.perf_counter(), time.process_time()
        summary = run_command(root / "data", args.scenario, Layout(root / "var"),
                              frame_seeds=args.frame_seeds)
        full_wall, full_cpu = time.perf_counter() - wall, time.process_time() - cpu
    row = summary.get("sensitivity", {}).get("human_relative_frame")
    print(f"pairs: {summary['pairs']}, seeds: {summary['seeds']}, human-relative frame row: "
          f"{row['seeds'] if row else 0} seeds")
    print(f"baseline, one Ours training: {base_wall:.1f} s wall, {base_cpu:.1f} s CPU")
    print(f"tomstudy interaction:        {full_wall:.1f} s wall, {full_cpu:.1f} s CPU")
    print(f"ratio full / one training: {full_wall / base_wall:.1f} (wall), "
          f"{full_cpu / base_cpu:.1f} (CPU)")
    verdict = "met" if full_wall < TARGET_S else "MISSED"
    print(f"target: whole command under {TARGET_S:.0f} s wall: {verdict}")


if __name__ == "__main__":
    main()
