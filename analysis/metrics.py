"""Alignment error between people's and models' predicted actions, and exclusion rules.

Only numpy and pandas: the researcher dashboard imports these for its running numbers.

Alignment error = 1 - cos(angle between two action vectors), in [0, 2]: 0 = same
direction, 1 = perpendicular, 2 = opposite. A cosine needs two directions; when either
vector is shorter than ZERO_SPEED_MPS (a model may predict standing still; a person
cannot, the server rejects zero-length moves) the error is defined as 1, the value of
"no directional information" (the mean error of a uniformly random direction), and such
rows are counted as `zero_vectors` so a report can say how often it happened.
"""

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field

MODELS = ("ours", "vae", "cv", "policy")
ZERO_SPEED_MPS = 1e-6
UNIT_KEYS = ["participant_id", "world"]


def alignment_error(a: np.ndarray, b: np.ndarray, zero_speed: float = ZERO_SPEED_MPS) -> np.ndarray:
    """1 - cos(angle) between action vectors a[..., 2] and b[..., 2]; 1 where either is ~0."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    norm_a = np.hypot(a[..., 0], a[..., 1])
    norm_b = np.hypot(b[..., 0], b[..., 1])
    defined = (norm_a > zero_speed) & (norm_b > zero_speed)
    dot = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.where(defined, dot / (norm_a * norm_b), 0.0)
    return 1.0 - np.clip(cos, -1.0, 1.0)


def add_alignment_errors(frame: pd.DataFrame, models: tuple[str, ...] = MODELS) -> pd.DataFrame:
    """A copy of `frame` with `err_<model>` columns: human action vs each model's action."""
    out = frame.copy()
    human = frame[["human_vx", "human_vy"]].to_numpy(np.float64)
    for model in models:
        other = frame[[f"{model}_vx", f"{model}_vy"]].to_numpy(np.float64)
        out[f"err_{model}"] = alignment_error(human, other)
    return out


def zero_vector_counts(frame: pd.DataFrame, models: tuple[str, ...] = MODELS) -> dict[str, int]:
    """How many rows each model (and the human column) has an action shorter than ZERO_SPEED_MPS."""
    counts = {}
    for who in ("human", *models):
        speed = np.hypot(frame[f"{who}_vx"].to_numpy(), frame[f"{who}_vy"].to_numpy())
        counts[who] = int(np.sum(~(speed > ZERO_SPEED_MPS)))
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


PILOT = "pilot"  # the recruitment of a researcher's preview session


class ExclusionRules(BaseModel):
    """Named exclusion rules, the study config's `exclusions` section (same keys).

    A participant is excluded for a failed attention check, an incomplete session, or
    more than `too_fast_max_fraction` of scored trials answered within `too_fast_trial_ms`;
    of the participants kept, single too-fast trials are dropped.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    failed_attention_check: bool = True
    incomplete: bool = True
    too_fast_trial_ms: float = Field(default=4000.0, ge=0)
    too_fast_max_fraction: float = Field(default=0.25, ge=0, le=1)


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
    """Apply each named rule explicitly; pilot sessions, practice and attention-check trials
    never count."""
    participants = frame.groupby("participant_id", sort=True)
    excluded: dict[str, list[str]] = {}
    pilot = participants["recruitment"].first() == PILOT  # researcher previews: never data
    excluded["pilot"] = sorted(pilot[pilot].index)
    if rules.failed_attention_check:
        failed = ~participants["attention_passed"].all()
        excluded["failed_attention_check"] = sorted(failed[failed].index)
    if rules.incomplete:
        incomplete = ~participants["completed"].all()
        excluded["incomplete"] = sorted(incomplete[incomplete].index)
    scored = frame[~frame["is_practice"] & ~frame["attention_check"]]
    trials = scored.drop_duplicates(["participant_id", "trial_id"])
    fast_trial = trials["trial_duration_ms"] < rules.too_fast_trial_ms
    fast_share = fast_trial.groupby(trials["participant_id"]).mean()
    too_fast = fast_share[fast_share > rules.too_fast_max_fraction]
    excluded["too_fast"] = sorted(too_fast.index)
    dropped_ids = set().union(*excluded.values())
    keep = scored[~scored["participant_id"].isin(dropped_ids)]
    fast_rows = keep["trial_duration_ms"] < rules.too_fast_trial_ms
    fast_trials_dropped = keep[fast_rows].drop_duplicates(["participant_id", "trial_id"])
    return Exclusions(
        kept=keep[~fast_rows].reset_index(drop=True),
        participants_total=int(frame["participant_id"].nunique()),
        participants_excluded=excluded,
        too_fast_trials_dropped=len(fast_trials_dropped),
        practice_rows_dropped=int(frame["is_practice"].sum()),
        attention_rows_dropped=int((~frame["is_practice"] & frame["attention_check"]).sum()),
    )
