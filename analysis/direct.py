"""The direct test of the claim, per world: do people align better with the coarse observers
than with the precise one?

The observers (app/observers/family.py) answer every trial once, with no model seeds. The
export holds each coarse variant's answers as a plug-in predictor's columns
(app/core/contracts.py `plugin_columns`: `coarse`, `coarse_scene`, `coarse_momentum`); the
precise observer is the world's own policy (`policy_vx`, `policy_vy`). Pre-registered rule,
per world, on the kept rows (the rows every other comparison reads):

- per coarse variant the export holds for the world: per (participant, trial) the mean of
  err_<variant> - err_policy, and Clark's min F' with participants and trials random
  (analysis/crossed.py), two-sided; the estimate with its 95% CI (the crossed SE);
- Holm's correction over the coarse variants present in the world;
- a variant's verdict: `coarse` where its Holm-adjusted p is below alpha and the
  participants' and the trials' mean differences are both negative (people align better with
  the coarse variant than with the precise observer), `precise` where it is significant and
  both are positive, else `neither`;
- the world's verdict: `coarse` if at least one variant's verdict is `coarse` and none is
  `precise`; `precise` if every variant's verdict is `precise`; else `neither`.

Rows where a variant has no answer (an export from before the observers) are left out of its
test; a world where no variant has answers is skipped.
"""

import numpy as np
import pandas as pd

from analysis.crossed import crossed_standard_error, crossed_test, crossed_verdicts
from analysis.equivalence import t_interval
from analysis.stats import holm, plain_records
from app.core.contracts import COARSE_OBSERVERS, plugin_names

PRECISE = "policy"  # the precise observer answers as the world's policy moves
CELL = ["participant_id", "trial_id"]


def observers_present(columns) -> list[str]:
    """The coarse variants whose plug-in columns the export holds, in COARSE_OBSERVERS order."""
    present = set(plugin_names(columns))
    return [name for name in COARSE_OBSERVERS if name in present]


def variant_test(rows: pd.DataFrame, variant: str) -> dict | None:
    """err_<variant> - err_policy in one world: min F' and the 95% CI (None without answers)."""
    answered = rows[rows[[f"{variant}_vx", f"{variant}_vy"]].notna().all(axis=1)]
    if answered.empty:
        return None
    cells = (answered.assign(diff=answered[f"err_{variant}"] - answered[f"err_{PRECISE}"])
             .groupby(CELL, sort=True)[["diff", f"err_{variant}", f"err_{PRECISE}"]].mean()
             .reset_index())
    result = crossed_test(cells["diff"], cells["participant_id"], cells["trial_id"])
    se, df = crossed_standard_error(cells["diff"], cells["participant_id"], cells["trial_id"])
    low, high = t_interval(result.mean_diff, se, df)
    return {"variant": variant, "err_variant": float(cells[f"err_{variant}"].mean()),
            "err_precise": float(cells[f"err_{PRECISE}"].mean()), **result.as_dict(),
            "ci95_low": low, "ci95_high": high}


def variant_verdicts(table: pd.DataFrame, alpha: float) -> np.ndarray:
    """Per variant: coarse, precise or neither at alpha on its Holm-adjusted p."""
    signs = crossed_verdicts({"p_two_sided": table["p_holm"].to_numpy(),
                              "t_participants": table["t_participants"].to_numpy(),
                              "t_trials": table["t_trials"].to_numpy()}, alpha)
    return np.where(signs < 0, "coarse", np.where(signs > 0, "precise", "neither"))


def world_verdict(verdicts) -> str:
    """coarse if a variant is coarse and none precise, precise if every one is, else neither."""
    verdicts = list(verdicts)
    if "coarse" in verdicts and "precise" not in verdicts:
        return "coarse"
    if verdicts and all(v == "precise" for v in verdicts):
        return "precise"
    return "neither"


def direct_table(kept: pd.DataFrame, alpha: float, exploratory: dict[str, str]) -> pd.DataFrame:
    """Per world and coarse variant present: the test, its Holm-adjusted p and verdict, the
    world's verdict and whether the world is exploratory (empty without observer columns).
    `kept` holds the err_ columns of analysis/metrics.py add_alignment_errors."""
    variants = observers_present(kept.columns)
    parts = []
    for world, rows in kept.groupby("world", sort=True):
        tests = [t for t in (variant_test(rows, v) for v in variants) if t is not None]
        if not tests:
            continue
        table = pd.DataFrame(tests)
        table.insert(0, "world", world)
        table["p_holm"] = holm(table["p_two_sided"])
        table["verdict"] = variant_verdicts(table, alpha)
        table["world_verdict"] = world_verdict(table["verdict"])
        table["exploratory"] = world in exploratory
        parts.append(table)
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def direct_summary(table: pd.DataFrame) -> dict:
    """summary.json's entry: per world its variants' rows, its verdict and whether it is
    exploratory."""
    out: dict = {}
    for row in plain_records(table):
        world = out.setdefault(row["world"], {"variants": {}, "verdict": row["world_verdict"],
                                              "exploratory": bool(row["exploratory"])})
        world["variants"][row["variant"]] = {k: v for k, v in row.items() if k not in (
            "world", "variant", "world_verdict", "exploratory")}
    return out
