"""Every predictor side by side over pilot reports: what `make pilot` runs' analyses found.

    python -m analysis.pilot_table var/reports/pilot_interaction_study_{coarse,precise,random}

Prints two markdown tables from each report folder's predictors.csv and pairwise.csv (written
by `tomstudy analyze`): the mean of the participants' alignment errors per predictor and
world, then every pair's paired test and mixed model with their Holm-corrected p-values.
"""

import argparse
from pathlib import Path

import pandas as pd

from analysis.predictors import REFERENCE


def pilot_name(folder: Path) -> str:
    """The bot kind a `make pilot` report folder is named after (its last word)."""
    return folder.name.rsplit("_", 1)[-1]


def means_table(folders: list[Path]) -> list[str]:
    """Mean alignment error per pilot, world and predictor (the policy as a reference)."""
    columns = pd.read_csv(folders[0] / "predictors.csv", nrows=0).columns
    names = [c.removeprefix("err_") for c in columns
             if c.startswith("err_") and c != f"err_{REFERENCE}"] + [REFERENCE]
    lines = ["| pilot | world | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for folder in folders:
        means = pd.read_csv(folder / "predictors.csv")
        for world, group in means.groupby("world", sort=True):
            cells = [f"{group[f'err_{name}'].mean():.3f}" for name in names]
            lines.append(f"| {pilot_name(folder)} | {world} | " + " | ".join(cells) + " |")
    return lines


def pairs_table(folders: list[Path]) -> list[str]:
    """Every pair's difference, 95% CI, Holm p, mixed model and verdict per pilot and world."""
    lines = ["| pilot | world | pair | diff a - b [95% CI] | p (Holm) | mixed model est, p (Holm) "
             "| verdict |", "|---|---|---|---|---|---|---|"]
    for folder in folders:
        for _, r in pd.read_csv(folder / "pairwise.csv").iterrows():
            lines.append(
                f"| {pilot_name(folder)} | {r.world} | {r.a} vs {r.b} | {r.mean_diff:+.4f} "
                f"[{r.ci95_low:+.4f}, {r.ci95_high:+.4f}] | {r.p_holm:.2g} | "
                f"{r.mixed_estimate:+.4f}, {r.mixed_p_holm:.2g} ({r.mixed_status}) | {r.verdict} |")
    return lines


def main() -> None:
    """Print both tables for the report folders given."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path)
    folders = parser.parse_args().folders
    print("\n".join([*means_table(folders), "", *pairs_table(folders)]))


if __name__ == "__main__":
    main()
