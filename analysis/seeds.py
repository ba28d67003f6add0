"""Ours vs the VAE per seed pair and for the model family (the mean over seeds).

The export carries the primary seed's answers; the trial bank stores every seed's. Each
kept row (participant, trial, start state, step) is joined to every seed's action for that
start state and step, but only rows whose `bank_sha256` is the loaded bank's: a row that
ran another bank is counted and left out, never matched by trial id alone.

- seed pair k: Ours' k-th seed vs the VAE's k-th seed (seed_index k of each family);
- family: per row, the mean over each model's seeds of its alignment error; per participant
  that is the mean over seeds of the participant's mean error, as every seed answers the
  same rows.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd

from analysis.bank import ANSWER_KEYS, Bank, seed_answers
from analysis.metrics import participant_means
from analysis.stats import PAIR, breakdown, with_verdicts
from app.core.alignment import alignment_error

ROW_KEYS = ["participant_id", "world", "trial_id", "arm", "start_index", "step"]
PRIMARY_TOLERANCE = 1e-6  # m/s: the export's primary answers vs the bank's, after float I/O


@dataclass
class SeedJoin:
    """Every seed's alignment error on the kept rows that ran the loaded bank, and what was
    left out. `errors`: one row per (kept row, model, seed) with `err`."""

    errors: pd.DataFrame
    bank_sha256: str
    rows_kept: int
    rows_matched: int
    rows_not_in_bank: int
    other_banks: dict[str, int]  # bank_sha256 -> rows that ran it (left out)
    participants_other_bank: list[str]
    primary_max_abs_diff: float  # export's ours/vae columns vs the bank's primary seed

    @property
    def status(self) -> str:
        """'ok', or why there is no per-seed result ('no_rows_on_this_bank')."""
        return "ok" if self.rows_matched else "no_rows_on_this_bank"

    def note(self) -> str:
        """One plain sentence on which rows the per-seed results use."""
        used = (f"{self.rows_matched} of {self.rows_kept} kept rows ran the loaded trial bank "
                f"({self.bank_sha256[:12]}) and are joined to every seed's answers")
        left = sum(self.other_banks.values())
        if left:
            used += (f"; {left} rows ({len(self.participants_other_bank)} participant(s)) ran "
                     f"another bank ({', '.join(h[:12] for h in self.other_banks)}) and are "
                     "left out of the per-seed and family results (the primary results use "
                     "them)")
        if self.rows_not_in_bank:
            used += (f"; {self.rows_not_in_bank} rows carry the bank's hash but name a "
                     "trial, start state or step it does not hold, and are left out")
        return used + "."

    def summary(self) -> dict:
        """The join's numbers for summary.json."""
        return {"status": self.status, "note": self.note(), "bank_sha256": self.bank_sha256,
                "rows_kept": self.rows_kept, "rows_matched": self.rows_matched,
                "rows_not_in_bank": self.rows_not_in_bank, "other_banks": self.other_banks,
                "participants_other_bank": self.participants_other_bank,
                "primary_max_abs_diff": self.primary_max_abs_diff}


def join_seeds(kept: pd.DataFrame, bank: Bank) -> SeedJoin:
    """Each kept row that ran `bank`, joined to every seed's answer, with its alignment error."""
    on_bank = kept["bank_sha256"] == bank.sha256
    others = kept.loc[~on_bank]
    answers = seed_answers(bank.data)
    rows = kept.loc[on_bank, [*ROW_KEYS, "participant_vx", "participant_vy", "ours_vx",
                              "ours_vy", "vae_vx", "vae_vy"]]
    joined = rows.merge(answers, on=ANSWER_KEYS, how="inner")
    participant = joined[["participant_vx", "participant_vy"]].to_numpy(np.float64)
    joined["err"] = alignment_error(participant, joined[["vx", "vy"]].to_numpy(np.float64))
    matched = int(joined[ROW_KEYS].drop_duplicates().shape[0])
    return SeedJoin(
        errors=joined[[*ROW_KEYS, "model", "seed_index", "seed", "err"]],
        bank_sha256=bank.sha256, rows_kept=len(kept), rows_matched=matched,
        rows_not_in_bank=int(on_bank.sum()) - matched,
        other_banks={h: int(n) for h, n in others["bank_sha256"].value_counts().sort_index()
                     .items()},
        participants_other_bank=sorted(others["participant_id"].unique()),
        primary_max_abs_diff=_primary_difference(joined))


def _primary_difference(joined: pd.DataFrame) -> float:
    """Largest |export column - bank primary answer| (0 if nothing joined): the join's check."""
    primary = joined[joined["seed_index"] == 0]
    if primary.empty:
        return 0.0
    gaps = [np.abs(part[f"{model}_{axis}"] - part[axis]).max()
            for model, part in primary.groupby("model") for axis in ("vx", "vy")]
    return float(max(gaps))


def pair_rows(errors: pd.DataFrame) -> pd.DataFrame:
    """Per kept row and seed pair k: err_ours and err_vae of each family's k-th seed (pairs
    only as far as both families reach)."""
    wide = errors.pivot_table(index=[*ROW_KEYS, "seed_index"], columns="model", values="err",
                              aggfunc="first").dropna()
    wide.columns = [f"err_{m}" for m in wide.columns]
    return wide.reset_index().rename(columns={"seed_index": "pair"})


def family_rows(errors: pd.DataFrame) -> pd.DataFrame:
    """Per kept row: err_ours and err_vae as the mean over each model's seeds."""
    wide = errors.groupby([*ROW_KEYS, "model"], sort=True)["err"].mean().unstack("model")
    wide.columns = [f"err_{m}" for m in wide.columns]
    return wide.reset_index()


def pair_seeds(errors: pd.DataFrame) -> pd.DataFrame:
    """Per world and pair: the training seed of each side (columns ours_seed, vae_seed)."""
    seeds = errors.groupby(["world", "seed_index", "model"])["seed"].first().unstack("model")
    seeds.columns = [f"{m}_seed" for m in seeds.columns]
    return seeds.reset_index().rename(columns={"seed_index": "pair"})


def per_seed_table(errors: pd.DataFrame) -> pd.DataFrame:
    """Per world and seed pair: the paired Ours-vs-VAE comparison across participants."""
    means = participant_means(pair_rows(errors), models=PAIR, by=("pair",))
    table = breakdown(means, ["world", "pair"], models=PAIR)
    return with_verdicts(table.merge(pair_seeds(errors), on=["world", "pair"], how="left"))


def family_table(family: pd.DataFrame, errors: pd.DataFrame) -> pd.DataFrame:
    """Per world: the paired comparison of each participant's mean over seeds, and how many
    seeds each family has."""
    table = with_verdicts(breakdown(participant_means(family, models=PAIR), ["world"],
                                    models=PAIR))
    counts = errors.groupby(["world", "model"])["seed_index"].nunique().unstack("model")
    counts.columns = [f"{m}_seeds" for m in counts.columns]
    return table.merge(counts.reset_index(), on="world", how="left")


def verdict_counts(per_seed: pd.DataFrame) -> dict:
    """Per world: how many seed pairs favour Ours, favour the VAE, or neither at ALPHA."""
    counts = per_seed.groupby("world")["verdict"].value_counts().unstack(fill_value=0)
    return {world: {v: int(row.get(v, 0)) for v in ("ours", "vae", "neither")}
            for world, row in counts.iterrows()}


@dataclass
class SeedResults:
    """The per-seed part of a report: how rows were joined, the tables, the family's rows."""

    join: dict  # status ('ok', 'no_bank', 'no_rows_on_this_bank'), note and counts
    per_seed: pd.DataFrame
    family: pd.DataFrame
    family_rows: pd.DataFrame | None  # per kept row on the bank: err_ours, err_vae over seeds

    @property
    def ok(self) -> bool:
        """Whether there are per-seed and family results."""
        return self.join["status"] == "ok"


def seed_results(kept: pd.DataFrame, bank: Bank | None, bank_path: str) -> SeedResults:
    """Per seed pair and family results on the kept rows that ran `bank` (none without it)."""
    if bank is None:
        note = f"no trial bank at {bank_path}: per-seed and family results are not computed."
        return SeedResults({"status": "no_bank", "note": note}, pd.DataFrame(), pd.DataFrame(),
                           None)
    join = join_seeds(kept, bank)
    if join.status != "ok":
        return SeedResults(join.summary(), pd.DataFrame(), pd.DataFrame(), None)
    rows = family_rows(join.errors)
    return SeedResults(join.summary(), per_seed_table(join.errors),
                       family_table(rows, join.errors), rows)
