"""Simulated studies run in process (no HTTP): power to find Ours < VAE, the instrument check.

The observer presets (app/observers/inverse_planning.py) answer the trial bank's trials
directly; the models' answers are the bank's precomputed actions, exactly what the server
stores beside a participant's.
The rows have the export CSV's columns, so the same analysis code scores them.
Power at n = the share of `reps` studies of n participants (drawn with replacement from a
simulated pool) where the one-sided paired t-test gives p < alpha in that world.

The instrument check (`run_instrument`) asks whether the study can tell the two observer
presets apart at all: n coarse and n precise simulated participants, per world the
per-participant err_ours - err_vae of each population, and Welch's one-sided t-test that
the coarse population's difference is lower (alpha 0.01), plus the same test for the
relative lane reading (`coarse_relative`) as a sensitivity row.
"""

import warnings
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import permutations
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from tqdm import tqdm

from analysis.load import normalise
from analysis.metrics import add_alignment_errors, participant_means
from analysis.plots import plot_power, plot_trial_contrast
from app.assignment import least_used, pick_by_arm
from app.core.alignment import alignment_error
from app.core.contracts import EXPORT_COLUMNS, EXPORT_VERSION, RENAMED_COLUMNS
from app.core.files import write_json
from app.observers import inverse_planning
from app.observers.config import ObserversConfig, default_observers
from app.study.clicks import check_points, clicks_to_actions, robot_starts
from app.study.prediction_rows import MODELS, prediction_columns
from app.study.trial_payload import trial_payload
from app.study.trials import TrialBank, TrialRecord

SIMULATED_TRIAL_MS = 20000.0
INSTRUMENT_POPULATIONS = ("coarse", "precise", "coarse_relative")
INSTRUMENT_ROWS = (("absolute", "coarse"), ("relative", "coarse_relative"))  # reading, preset


def load_bank(path: Path) -> TrialBank:
    """A trial bank (bank.json, or a bundle's bank.json.gz), read as the server reads it."""
    return TrialBank.read(path)


def simulated_payload(bank: TrialBank, trial: TrialRecord) -> dict:
    """What the server sends for a trial (`trial_payload`), with the bank's trial id and world."""
    return {**trial_payload(bank, trial), "trial_id": trial.trial_id, "world": trial.world}


def check_answer(bank: TrialBank, trial: TrialRecord, clicks: np.ndarray) -> None:
    """Refuse (Refused 422) a simulated answer the server would refuse: its click check."""
    check_points(bank.world(trial.world), robot_starts(trial), clicks)


def answer_columns(bank: TrialBank, trial: TrialRecord, clicks: np.ndarray
                   ) -> dict[str, np.ndarray]:
    """A checked simulated answer turned into rows as the server stores a live one (every
    predictor's primary answer, as the server stores: the models' and each plug-in's)."""
    return prediction_columns(trial, trial.primaries(), clicks, bank.world(trial.world).dt_s)


def trial_rows(participant: str, answered: "SimulatedTrial", bank: TrialBank
               ) -> dict[str, np.ndarray]:
    """Export-shaped columns for one answered trial (K x n rows)."""
    trial, clicks = answered.trial, answered.clicks
    cols = answer_columns(bank, trial, clicks)
    size = clicks.shape[0] * clicks.shape[1]
    return cols | {
        "participant_id": np.full(size, participant), "world": np.full(size, trial.world),
        "world_position": np.full(size, answered.world_position),
        "trial_id": np.full(size, trial.trial_id), "arm": np.full(size, trial.arm),
        "trial_index": np.full(size, answered.trial_index),
        "click_time_ms": np.arange(1, size + 1) * SIMULATED_TRIAL_MS / size,
        "clip_sha256": np.full(size, trial.clip_sha256)}


@dataclass(frozen=True)
class SimulatedTrial:
    """One main trial a simulated participant answered."""

    participant: int
    world_position: int
    trial_index: int
    trial: TrialRecord  # the bank's trial
    payload: dict  # what the server would send (simulated_payload)
    clicks: np.ndarray  # [K, n, 2] clicked positions


def main_trials(bank: TrialBank) -> dict[str, dict[str, tuple[TrialRecord, dict]]]:
    """Per world, main trial id -> (trial, payload), in bank order."""
    return {world: {t.trial_id: (t, simulated_payload(bank, t))
                    for t in bank.trials_of(world, "main")}
            for world in sorted(bank.data.worlds)}


def simulated_trials(bank: TrialBank, preset: str, n: int, trials_per_world: int, seed: int = 0,
                     show_progress: bool = True, observers: ObserversConfig | None = None,
                     readings: dict | None = None) -> Iterator[SimulatedTrial]:
    """Every main trial `n` simulated participants of one observer preset answer, in order.

    Trials are assigned as the server assigns them (least seen first within each selection
    arm), so every trial is seen about equally often, as in the real study; world orders are
    counterbalanced the same way (the server's `counterbalance_world_order: true`). A coarse
    preset's reading of a trial is deterministic; `readings` (trial id -> reading) may carry
    them over from an earlier call with the same inference settings and lane reading."""
    observers = observers or default_observers()
    rng = np.random.default_rng(seed)
    main = main_trials(bank)
    relative = inverse_planning.reads_relative(preset, observers)
    readings = {} if readings is None else readings
    orders, order_use, exposure = list(permutations(main)), Counter(), Counter()
    for p in tqdm(range(n), desc=f"{preset} participants", disable=not show_progress):
        order = least_used(orders, order_use, 1, rng)[0]
        order_use[order] += 1
        for position, world in enumerate(order):
            arms = [(tid, trial.arm) for tid, (trial, _) in main[world].items()]
            chosen = pick_by_arm(arms, exposure, trials_per_world, rng)
            exposure.update(chosen)
            for index, trial_id in enumerate(chosen):
                trial, payload = main[world][trial_id]
                if preset.startswith("coarse") and trial_id not in readings:
                    readings[trial_id] = inverse_planning.trial_reading(
                        payload, observers, relative, inverse_planning.preset_route(preset))
                clicks = inverse_planning.predict(preset, payload, rng, trial.policy_actions,
                                                  observers, readings.get(trial_id))
                check_answer(bank, trial, clicks)  # the instrument grid's answers too
                yield SimulatedTrial(p, position, index, trial, payload, clicks)


def simulate_participants(bank: TrialBank, preset: str, n: int, trials_per_world: int,
                          seed: int = 0, show_progress: bool = True,
                          observers: ObserversConfig | None = None) -> pd.DataFrame:
    """Rows of `n` simulated participants of one observer preset, in the export CSV's columns
    (`simulated_trials`)."""
    parts = [trial_rows(f"sim-{s.participant:05d}", s, bank)
             for s in simulated_trials(bank, preset, n, trials_per_world, seed, show_progress,
                                       observers)]
    return export_frame(parts, bank.data.study_id, preset)


def export_frame(parts: list[dict[str, np.ndarray]], study_id: str, preset: str) -> pd.DataFrame:
    """Concatenate per-trial columns (stored names, renamed as the export names them) and fill
    the constant export columns."""
    cols = {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
    frame = pd.DataFrame(cols).rename(columns=RENAMED_COLUMNS)
    size = len(frame)
    constants = {"export_version": EXPORT_VERSION, "study_id": study_id,
                 "recruitment": "simulated", "completed": True,
                 "outcome": "completed", "replaced": False, "config_sha256": "", "bank_sha256": "",
                 "attention_passed": True, "is_practice": False, "attention_check": False,
                 "trial_duration_ms": SIMULATED_TRIAL_MS, "replays": 0, "submitted_at": "",
                 "click_input": "", "prolific_check": ""}  # no device placed these clicks
    for name, value in constants.items():
        frame[name] = np.full(size, value)
    frame["submission_id"] = frame["participant_id"] + "/" + frame["trial_id"] + f"/{preset}"
    return normalise(frame[list(EXPORT_COLUMNS)])


def power_curve(means: pd.DataFrame, n_values: list[int], reps: int = 2000, alpha: float = 0.01,
                seed: int = 0) -> pd.DataFrame:
    """Per world and n, the share of resampled studies where Ours < VAE at p < alpha."""
    rng = np.random.default_rng(seed)
    rows = []
    for world, group in means.groupby("world", sort=True):
        diff = (group["err_ours"] - group["err_vae"]).to_numpy()
        for n in n_values:
            sample = diff[rng.integers(len(diff), size=(reps, n))]
            with warnings.catch_warnings():  # scipy warns on draws of one repeated value
                warnings.simplefilter("ignore", RuntimeWarning)
                test = stats.ttest_1samp(sample, 0.0, axis=1, alternative="less")
            # Draws of one value: t is -inf/+inf (p 0/1), or NaN if that value is 0 (no effect)
            p = np.nan_to_num(test.pvalue, nan=1.0)
            rows.append({"world": world, "n": n, "power": float(np.mean(p < alpha)),
                         "mean_diff": float(diff.mean()),
                         "d_z": float(diff.mean() / diff.std(ddof=1))})
    return pd.DataFrame(rows)


def run_power(bank_path: Path, preset: str, trials_per_world: int, out_dir: Path, n_max: int = 60,
              pool: int = 400, reps: int = 2000, alpha: float = 0.01, seed: int = 0,
              observers: ObserversConfig | None = None) -> dict:
    """Simulate a pool of participants, estimate power vs n, write power.json/.csv and a plot."""
    bank = load_bank(bank_path)
    frame = simulate_participants(bank, preset, pool, trials_per_world, seed, observers=observers)
    means = participant_means(frame)
    n_values = list(range(3, n_max + 1))
    curve = power_curve(means, n_values, reps, alpha, seed)
    curve["power_trials_random"] = trials_random_power(bank, preset, curve, trials_per_world,
                                                       alpha, observers, seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    curve.to_csv(out_dir / "power.csv", index=False)
    figures = plot_power(curve, alpha, preset, out_dir / "power")
    needed = {world: _smallest_n(group, 0.8) for world, group in curve.groupby("world")}
    summary = {"kind": preset, "alpha": alpha, "pool": pool, "reps": reps, "seed": seed,
               "bank_sha256": bank.sha256,  # of the JSON, as sessions record it
               "trials_per_world": trials_per_world, "n_for_power_0.8": needed,
               "d_z": curve.groupby("world")["d_z"].first().to_dict(),
               "power_at": {f"{w}@{n}": float(g.loc[g["n"] == n, "power"].iloc[0])
                            for w, g in curve.groupby("world") for n in (10, 22, n_max)
                            if n in set(g["n"])},
               "n_for_power_0.8_trials_random": {
                   world: _smallest_n(group, 0.8, "power_trials_random")
                   for world, group in curve.groupby("world")},
               "figures": [str(f) for f in figures]}
    write_json(out_dir / "power.json", summary)
    return summary


def _smallest_n(group: pd.DataFrame, target: float, column: str = "power") -> int | None:
    reached = group[group[column] >= target]
    return int(reached["n"].min()) if len(reached) else None


TRIALS_RANDOM_REPS = 200


def trials_random_power(bank: TrialBank, preset: str, curve: pd.DataFrame,
                        trials_per_world: int, alpha: float, observers: ObserversConfig | None,
                        seed: int) -> list[float]:
    """Per row of `curve` (world, n): P(the primary test, the family with participants and trials
    random, concludes Ours) at the bank's size (app/observers/design_goal.py); NaN for a preset
    outside the observer family."""
    from app.observers.design_goal import Design, simulate_verdicts
    from app.observers.family import VARIANTS, world_answers
    from app.prediction_view import view_click_sd_deg

    if preset not in VARIANTS:
        return [float("nan")] * len(curve)
    observers = observers or default_observers()
    rng, out, answers = np.random.default_rng(seed), [], {}
    for world, n in curve[["world", "n"]].itertuples(index=False, name=None):
        if world not in answers:
            view = view_click_sd_deg(bank.world(world), observers.click_sd_px.value)
            answers[world] = world_answers(bank, world, observers, view, (preset,))
        found = answers[world]
        pool = np.arange(len(found.trial_ids))
        design = Design(int(n), len(pool), trials_per_world)
        verdicts = simulate_verdicts(found, preset, np.arange(len(found.seeds)), design, pool,
                                     TRIALS_RANDOM_REPS, alpha, rng)["crossed"]
        out.append(float(np.mean(verdicts == -1)))
    return out


def population_frames(bank: TrialBank, n: int, trials_per_world: int, seed: int,
                      observers: ObserversConfig, show_progress: bool = True
                      ) -> dict[str, pd.DataFrame]:
    """Rows, with each model's alignment error, of n simulated participants per population."""
    return {preset: add_alignment_errors(simulate_participants(
                bank, preset, n, trials_per_world, seed + offset, show_progress, observers))
            for offset, preset in enumerate(INSTRUMENT_POPULATIONS)}


def participant_diffs(frame: pd.DataFrame) -> pd.DataFrame:
    """Per participant and world: err_ours, err_vae and their difference."""
    means = participant_means(frame, ("ours", "vae"))[["participant_id", "world", "err_ours",
                                                       "err_vae"]]
    return means.assign(diff=means["err_ours"] - means["err_vae"])


def welch_row(world: str, reading: str, coarse: pd.DataFrame, precise: pd.DataFrame,
              alpha: float) -> dict:
    """One world's check: Welch's one-sided t-test that coarse's diff < precise's diff."""
    test = stats.ttest_ind(coarse["diff"], precise["diff"], equal_var=False, alternative="less")
    populations = {"coarse": coarse, "precise": precise}
    row = {"world": world, "reading": reading,
           **{f"n_{name}": len(pop) for name, pop in populations.items()}}
    for name, pop in populations.items():
        row.update({f"{name}_err_ours": float(pop["err_ours"].mean()),
                    f"{name}_err_vae": float(pop["err_vae"].mean()),
                    f"{name}_mean_diff": float(pop["diff"].mean()),
                    f"{name}_sd_diff": float(pop["diff"].std(ddof=1))})
    return {**row, "welch_t": float(test.statistic), "welch_df": float(test.df),
            "p_one_sided": float(test.pvalue), "passed": bool(test.pvalue < alpha)}


def welch_table(frames: dict[str, pd.DataFrame], alpha: float) -> pd.DataFrame:
    """Per world and lane reading, the check on the populations' simulated rows."""
    diffs = {preset: participant_diffs(frame) for preset, frame in frames.items()}
    rows = []
    for world in sorted(diffs["precise"]["world"].unique()):
        precise = diffs["precise"][diffs["precise"]["world"] == world]
        for reading, preset in INSTRUMENT_ROWS:
            coarse = diffs[preset][diffs[preset]["world"] == world]
            rows.append(welch_row(world, reading, coarse, precise, alpha))
    return pd.DataFrame(rows)


def instrument_check(bank: TrialBank, trials_per_world: int, n: int = 22, seed: int = 0,
                     alpha: float = 0.01, observers: ObserversConfig | None = None,
                     show_progress: bool = True) -> pd.DataFrame:
    """Per world and lane reading: can err_ours - err_vae tell coarse from precise observers?"""
    frames = population_frames(bank, n, trials_per_world, seed, observers or default_observers(),
                               show_progress)
    return welch_table(frames, alpha)


def replicate_check(bank: TrialBank, trials_per_world: int, n: int, seed: int, alpha: float,
                    observers: ObserversConfig, replications: int) -> pd.DataFrame:
    """The check rerun on `replications` fresh sets of simulated participants (new seeds):
    one row per replication, world and reading. Its pass rate is the check's power."""
    tables = []
    for r in tqdm(range(replications), desc="replications", disable=replications == 0):
        frames = population_frames(bank, n, trials_per_world,
                                   seed + len(INSTRUMENT_POPULATIONS) * (r + 1), observers, False)
        tables.append(welch_table(frames, alpha).assign(replication=r))
    columns = ["replication", "world", "reading", "welch_t", "p_one_sided", "passed"]
    return pd.concat(tables)[columns] if tables else pd.DataFrame(columns=columns)


def trial_contrast(frames: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Per world and main trial both populations saw: the coarse and the precise population's
    mean err_ours - err_vae over the participants who saw it, and their difference (where the
    check's contrast is)."""
    per_trial = {}
    for preset in ("coarse", "precise"):
        frame = frames[preset].assign(diff=frames[preset]["err_ours"] - frames[preset]["err_vae"])
        grouped = frame.groupby(["world", "trial_id"], sort=True)
        per_trial[preset] = pd.DataFrame({f"{preset}_diff": grouped["diff"].mean(),
                                          f"{preset}_participants":
                                              grouped["participant_id"].nunique()})
    table = per_trial["coarse"].join(per_trial["precise"], how="inner").reset_index()
    return table.assign(contrast=table["coarse_diff"] - table["precise_diff"])


def start_state_answers(bank: TrialBank, seed: int, observers: ObserversConfig) -> pd.DataFrame:
    """Per main-trial start state: each model's and each observer preset's actions [n, 2]."""
    rows = []
    for world in sorted(bank.data.worlds):
        dt_s = bank.world(world).dt_s
        for trial in bank.trials_of(world, "main"):
            payload = simulated_payload(bank, trial)
            clicks = {preset: inverse_planning.predict(
                preset, payload, np.random.default_rng(seed), trial.policy_actions, observers)
                for preset in ("coarse", "precise")}
            acts = {p: clicks_to_actions(robot_starts(trial), c, dt_s) for p, c in clicks.items()}
            acts |= {m: np.asarray(trial.primary(m).actions, dtype=np.float64) for m in MODELS}
            for k, state in enumerate(trial.start_states):
                rows.append({"world": world, "start_kind": state.start_kind,
                             **{name: a[k] for name, a in acts.items()}})
    return pd.DataFrame(rows)


def separation(bank: TrialBank, seed: int = 0, observers: ObserversConfig | None = None
               ) -> pd.DataFrame:
    """What the metric can tell apart, per world and start kind (and `all`): how far apart the
    two models' answers are, how far apart the two observers' clicks are (mean 1-cos), and each
    observer's err_ours - err_vae. The check can only separate observers where both gaps exist."""
    answers = start_state_answers(bank, seed, observers or default_observers())

    def gap(a: str, b: str, frame: pd.DataFrame) -> np.ndarray:
        return alignment_error(np.stack(frame[a].to_list()), np.stack(frame[b].to_list())
                               ).mean(axis=1)

    out = []
    for world, frame in answers.groupby("world", sort=True):
        groups = [*frame.groupby("start_kind", sort=True), ("all", frame)]
        for kind, part in groups:
            diffs = {obs: gap(obs, "ours", part) - gap(obs, "vae", part)
                     for obs in ("coarse", "precise")}
            out.append({"world": world, "start_kind": kind, "n_starts": len(part),
                        "ours_vs_vae": float(gap("ours", "vae", part).mean()),
                        "coarse_vs_precise": float(gap("coarse", "precise", part).mean()),
                        "coarse_diff": float(diffs["coarse"].mean()),
                        "precise_diff": float(diffs["precise"].mean())})
    return pd.DataFrame(out)


def run_instrument(bank_path: Path, trials_per_world: int, out_dir: Path, n: int = 22,
                   seed: int = 0, alpha: float = 0.01,
                   observers: ObserversConfig | None = None, replications: int = 50) -> dict:
    """Run the instrument check on a bank (and `replications` reruns for its pass rate); write
    instrument.json, instrument.csv, separation.csv, by_trial.csv, replications.csv and a
    figure of where the contrast is."""
    observers = observers or default_observers()
    bank_path = Path(bank_path)
    bank = load_bank(bank_path)
    frames = population_frames(bank, n, trials_per_world, seed, observers)
    table = welch_table(frames, alpha)
    by_trial = trial_contrast(frames)
    reruns = replicate_check(bank, trials_per_world, n, seed, alpha, observers, replications)
    rates = reruns.groupby(["world", "reading"])["passed"].mean()
    table["pass_rate"] = [rates.get(key) for key in  # None without replications
                          table[["world", "reading"]].itertuples(index=False, name=None)]
    gaps = separation(bank, seed, observers)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, frame in (("instrument", table), ("separation", gaps), ("by_trial", by_trial),
                        ("replications", reruns)):
        frame.to_csv(out_dir / f"{name}.csv", index=False)
    figures = plot_trial_contrast(by_trial, out_dir / "by_trial")
    main = table[table["reading"] == "absolute"]
    summary = {"n_per_population": n, "seed": seed, "alpha": alpha,
               "trials_per_world": trials_per_world, "bank": str(bank_path),
               "bank_sha256": bank.sha256,  # of the JSON, as sessions record it
               "test": "Welch t, one-sided: coarse err_ours-err_vae < precise err_ours-err_vae",
               "passed": {row["world"]: row["passed"] for _, row in main.iterrows()},
               "replications": replications,
               "pass_rate": {row["world"]: row["pass_rate"] for _, row in main.iterrows()},
               "rows": table.to_dict(orient="records"),
               "separation": gaps.to_dict(orient="records"),
               "figures": [str(f) for f in figures], "observers": observers.model_dump()}
    write_json(out_dir / "instrument.json", summary)
    return summary
