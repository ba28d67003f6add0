"""Alignment errors over the predictions table, per-participant means, exclusions, and the
subsets (world, selection arm) a comparison is read in.

The metric is defined once in app/core/alignment.py, the exclusion rules in
app/core/contracts.py. Rows where a vector is shorter than ZERO_SPEED_MPS are counted as
`zero_vectors`, so a report can say how often the error fell back to 1. Only numpy and
pandas: the researcher dashboard imports these for its running numbers.
"""

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from app.core.alignment import alignment_error, has_direction
from app.core.contracts import (
    MODELS,
    PILOT,
    PROLIFIC_UNCONFIRMED,
    ExclusionRules,
    plugin_names,
    too_fast_share_exceeds,
)

UNIT_KEYS = ["participant_id", "world"]


def add_alignment_errors(frame: pd.DataFrame,
                         models: tuple[str, ...] | None = None) -> pd.DataFrame:
    """A copy of `frame` with `err_<model>` columns: the participant's action vs each model's
    action (by default the contract's MODELS and every plug-in predictor the rows hold)."""
    if models is None:
        models = (*MODELS, *plugin_names(frame.columns))
    out = frame.copy()
    participant = frame[["participant_vx", "participant_vy"]].to_numpy(np.float64)
    for model in models:
        other = frame[[f"{model}_vx", f"{model}_vy"]].to_numpy(np.float64)
        out[f"err_{model}"] = alignment_error(participant, other)
    return out


def zero_vector_counts(frame: pd.DataFrame, models: tuple[str, ...] = MODELS) -> dict[str, int]:
    """How many rows each model (and the participant) has an action shorter than
    ZERO_SPEED_MPS."""
    counts = {}
    for who in ("participant", *models):
        counts[who] = int(np.sum(~has_direction(frame[[f"{who}_vx", f"{who}_vy"]].to_numpy())))
    return counts


def participant_means(frame: pd.DataFrame, models: tuple[str, ...] = MODELS,
                      by: tuple[str, ...] = ()) -> pd.DataFrame:
    """Mean alignment error per participant x world (x each `by` column, e.g. start_kind)
    x model: one row per participant and world (and `by` value)."""
    if not any(c.startswith("err_") for c in frame.columns):
        frame = add_alignment_errors(frame, models)
    cols = [f"err_{m}" for m in models]
    grouped = frame.groupby([*UNIT_KEYS, *by], sort=True)
    means = grouped[cols].mean()
    means["n_rows"] = grouped.size()
    means["n_trials"] = grouped["trial_id"].nunique()
    return means.reset_index()


@dataclass
class Exclusions:
    """What the rules removed: participants per rule, too-fast trials, and the rows kept."""

    kept: pd.DataFrame
    participants_total: int
    participants_excluded: dict[str, list[str]] = field(default_factory=dict)
    too_fast_trials_dropped: int = 0
    practice_rows_dropped: int = 0
    attention_rows_dropped: int = 0

    def counts(self) -> dict[str, int]:
        """Numbers for the report: excluded participants per rule and dropped trials."""
        excluded = set().union(*self.participants_excluded.values())
        return {
            "participants_total": self.participants_total,
            **{f"excluded_{rule}": len(ids) for rule, ids in self.participants_excluded.items()},
            "participants_excluded": len(excluded),
            "participants_kept": int(self.kept["participant_id"].nunique()),
            "too_fast_trials_dropped": self.too_fast_trials_dropped,
            "practice_rows_dropped": self.practice_rows_dropped,
            "attention_check_rows_dropped": self.attention_rows_dropped,
            "rows_kept": len(self.kept),
        }


def apply_exclusions(frame: pd.DataFrame, rules: ExclusionRules) -> Exclusions:
    """Apply each named rule explicitly; pilot sessions, replaced attempts (the person went
    on in a newer one), sessions Prolific did not confirm (prolific_unknown), practice and
    attention-check trials never count."""
    participants = frame.groupby("participant_id", sort=True)
    excluded: dict[str, list[str]] = {}
    pilot = participants["recruitment"].first() == PILOT  # researcher previews: never data
    excluded["pilot"] = sorted(pilot[pilot].index)
    replaced = participants["replaced"].any()
    excluded["replaced"] = sorted(replaced[replaced].index)
    unknown = participants["prolific_check"].first().isin(PROLIFIC_UNCONFIRMED)
    excluded["prolific_unknown"] = sorted(unknown[unknown].index)
    if rules.failed_attention_check:
        failed = ~participants["attention_passed"].all()
        excluded["failed_attention_check"] = sorted(failed[failed].index)
    if rules.incomplete:
        incomplete = ~participants["completed"].all()
        excluded["incomplete"] = sorted(incomplete[incomplete].index)
    scored = frame[~frame["is_practice"] & ~frame["attention_check"]]
    trials = scored.drop_duplicates(["participant_id", "trial_id"])
    fast_trial = rules.too_fast(trials["trial_duration_ms"])
    fast = fast_trial.groupby(trials["participant_id"]).agg(["sum", "count"])
    too_fast = too_fast_share_exceeds(fast["sum"], fast["count"], rules)
    excluded["too_fast"] = sorted(fast.index[too_fast])
    dropped_ids = set().union(*excluded.values())
    keep = scored[~scored["participant_id"].isin(dropped_ids)]
    fast_rows = rules.too_fast(keep["trial_duration_ms"])
    fast_trials_dropped = keep[fast_rows].drop_duplicates(["participant_id", "trial_id"])
    return Exclusions(
        kept=keep[~fast_rows].reset_index(drop=True),
        participants_total=int(frame["participant_id"].nunique()),
        participants_excluded=excluded,
        too_fast_trials_dropped=len(fast_trials_dropped),
        practice_rows_dropped=int(frame["is_practice"].sum()),
        attention_rows_dropped=int((~frame["is_practice"] & frame["attention_check"]).sum()),
    )


POOLED = "pooled"


def answer_subsets(answer_sets: dict[str, pd.DataFrame]) -> Iterator[tuple[dict, pd.DataFrame]]:
    """Each (world, arm, answers) subset of the rows, in that order, as (labels, rows): per
    world, the arms pooled first, then each selection arm (an older export's '' arm is only
    pooled); `answer_sets` maps a name (e.g. primary, family) to rows with err_ columns."""
    frames = list(answer_sets.values())
    worlds = sorted(set().union(*(f["world"].unique() for f in frames)))
    arms = sorted(set().union(*(f["arm"].unique() for f in frames)) - {""})
    for world in worlds:
        for arm in (POOLED, *arms):
            for answers, rows in answer_sets.items():
                in_arm = (rows["arm"] == arm) | (arm == POOLED)
                subset = rows[(rows["world"] == world) & in_arm]
                if len(subset):
                    yield {"world": world, "arm": arm, "answers": answers}, subset
