"""Time `tomstudy analyze` on 300,000 predictions against just reading the same CSV.

1,000 simulated participants x 20 trials x 5 start states x 3 steps, answered by the
coarse observers run in process on the trial bank of the bundle the study is served from
(the paper's ships with the code). Prints both wall times and their ratio; target: the
whole analysis (load, exclusions, errors, tests, ADE/FDE, figures, report) under 10 s.

    .venv/bin/python benchmarks/bench_analysis.py [--participants 1000] [--study paper_study]
"""

import argparse
import tempfile
import time
from pathlib import Path

import pandas as pd

from analysis.report import run_analyze
from app.bank.served import analysis_inputs, served_bank
from app.observers.simulated_study import load_bank, simulate_participants
from app.settings import get_settings

TARGET_S = 10.0


def main() -> None:
    """Generate the rows, then time the CSV read (baseline) and the whole analysis."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, default=1000)
    parser.add_argument("--study", default="paper_study")
    args = parser.parse_args()
    settings = get_settings()
    frame = simulate_participants(load_bank(served_bank(settings, args.study)), "coarse",
                                  args.participants, 10, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "export.csv"
        frame.to_csv(csv, index=False)
        start = time.perf_counter()
        pd.read_csv(csv)
        baseline = time.perf_counter() - start
        start = time.perf_counter()
        run_analyze(args.study, Path(tmp) / "report", csv, "",
                    analysis_inputs(settings, args.study))
        analysis = time.perf_counter() - start
    print(f"rows: {len(frame):,} ({args.participants} participants x 20 trials x 5 x 3)")
    print(f"baseline pd.read_csv: {baseline:.2f} s")
    print(f"tomstudy analyze (all outputs): {analysis:.2f} s")
    print(f"ratio analyze / read_csv: {analysis / baseline:.2f}x; "
          f"target < {TARGET_S:.0f} s: {'met' if analysis < TARGET_S else 'NOT met'}")


if __name__ == "__main__":
    main()
