"""Per seed pair, family and per arm results against by-hand computations on a tiny bank."""

import gzip
import hashlib

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.bank import Bank, family_hashes, read_bank, seed_answers
from analysis.metrics import add_alignment_errors
from analysis.seeds import (
    family_rows,
    family_table,
    join_seeds,
    per_seed_table,
    seed_results,
    verdict_counts,
)
from analysis.stats import by_arm_table, compare_per_world, paired_comparison, verdicts
from tests.analysis.fixed_data import (
    cos_distance,
    family_bank,
    fixed_predictions,
    on_bank,
    small_bank,
)

SEEDS = {"ours": [7, 8, 9], "vae": [3, 4]}  # unequal families: 2 pairs, family over 3 and 2


@pytest.fixture
def study():
    """Rows of 4 participants answered from a bank with 3 Ours and 2 VAE seeds."""
    frame = fixed_predictions(n_participants=4, trials=2, starts=2, steps=3)
    bank = family_bank(frame, SEEDS, seed=1)
    frame, raw = on_bank(frame, bank)
    return frame, Bank(bank, hashlib.sha256(raw).hexdigest()), raw


def _by_hand_means(frame, bank: dict, model: str, index: int, world: str) -> np.ndarray:
    """Per participant: mean alignment error of one seed's answers, by loops."""
    trials = {t["trial_id"]: t for t in bank["worlds"][world]["trials"]}
    means = []
    for pid in sorted(frame["participant_id"].unique()):
        rows = frame[(frame["participant_id"] == pid) & (frame["world"] == world)]
        errs = [cos_distance((r.participant_vx, r.participant_vy),
                             trials[r.trial_id]["predictions"][model][index]["actions"]
                             [r.start_index][r.step])
                for r in rows.itertuples()]
        means.append(sum(errs) / len(errs))
    return np.array(means)


def test_a_gzipped_bank_reads_as_its_json_with_the_json_hash(study, tmp_path):
    _, bank, raw = study
    (tmp_path / "bank.json").write_bytes(raw)
    (tmp_path / "bank.json.gz").write_bytes(gzip.compress(raw))
    plain, zipped = read_bank(tmp_path / "bank.json"), read_bank(tmp_path / "bank.json.gz")
    assert plain.sha256 == zipped.sha256 == bank.sha256
    assert zipped.data == bank.data
    assert read_bank(tmp_path / "absent.json.gz") is None


def test_an_old_bank_reads_as_a_family_of_one():
    old = small_bank(trials=2)  # one answer per model, as banks before model families held
    for world in old["worlds"].values():
        for trial in world["trials"]:
            trial["predictions"] = {m: family[0] for m, family in trial["predictions"].items()}
    answers = seed_answers(old)
    assert set(answers["seed_index"]) == {0}
    assert len(answers) == 2 * 2 * 2 * 5 * 3  # worlds x trials x models x K x n


def test_per_seed_pairs_and_family_match_a_hand_computation(study):
    frame, bank, _ = study
    join = join_seeds(frame, bank)
    assert join.rows_matched == len(frame) and join.primary_max_abs_diff < 1e-12
    per_seed = per_seed_table(join.errors).set_index(["world", "pair"])
    family = family_table(family_rows(join.errors), join.errors).set_index("world")
    for world in ("highway", "obstacle"):
        ours = [_by_hand_means(frame, bank.data, "ours", k, world) for k in range(3)]
        vae = [_by_hand_means(frame, bank.data, "vae", k, world) for k in range(2)]
        assert sorted(per_seed.loc[world].index) == [0, 1]  # pairs only as far as both reach
        for k in range(2):
            row = per_seed.loc[(world, k)]
            assert (row["ours_seed"], row["vae_seed"]) == (SEEDS["ours"][k], SEEDS["vae"][k])
            assert row["err_ours"] == pytest.approx(ours[k].mean(), rel=1e-12)
            assert row["mean_diff"] == pytest.approx((ours[k] - vae[k]).mean(), rel=1e-12)
            assert row["t"] == pytest.approx(stats.ttest_rel(ours[k], vae[k]).statistic,
                                             rel=1e-10)
        fam_ours, fam_vae = np.mean(ours, axis=0), np.mean(vae, axis=0)
        row = family.loc[world]
        assert (row["ours_seeds"], row["vae_seeds"]) == (3, 2)
        assert row["err_ours"] == pytest.approx(fam_ours.mean(), rel=1e-12)
        assert row["err_vae"] == pytest.approx(fam_vae.mean(), rel=1e-12)
        assert row["p_two_sided"] == pytest.approx(stats.ttest_rel(fam_ours, fam_vae).pvalue,
                                                   rel=1e-10)


def test_the_primary_pair_reproduces_the_export_columns(study):
    frame, bank, _ = study
    per_seed = per_seed_table(join_seeds(frame, bank).errors)
    primary = compare_per_world(add_alignment_errors(frame).groupby(
        ["participant_id", "world"])[["err_ours", "err_vae"]].mean().reset_index())
    assert set(primary) == {"highway", "obstacle"}
    for world, res in primary.items():
        row = per_seed[(per_seed["world"] == world) & (per_seed["pair"] == 0)].iloc[0]
        assert row["mean_diff"] == pytest.approx(res.mean_diff, rel=1e-12)


def test_rows_from_another_bank_are_counted_and_left_out(study):
    frame, bank, _ = study
    frame = frame.copy()
    frame.loc[frame["participant_id"] == "p01", "bank_sha256"] = "0" * 64
    results = seed_results(frame, bank, "bank.json.gz")
    join = results.join
    assert join["participants_other_bank"] == ["p01"]
    assert join["other_banks"] == {"0" * 64: int((frame["participant_id"] == "p01").sum())}
    assert join["rows_matched"] == int((frame["participant_id"] != "p01").sum())
    assert "left out" in join["note"] and "000000000000" in join["note"]
    assert set(results.per_seed["n"]) == {3} and set(results.family["n"]) == {3}


def test_a_bank_whose_answers_differ_from_the_export_shows_in_the_check(study):
    frame, bank, _ = study
    frame = frame.copy()
    frame["ours_vx"] += 0.25
    assert join_seeds(frame, bank).primary_max_abs_diff == pytest.approx(0.25)


def test_without_a_bank_or_matching_rows_there_is_a_status_not_a_result(study):
    frame, bank, _ = study
    absent = seed_results(frame, None, "var/bank.json.gz")
    assert absent.join["status"] == "no_bank" and "var/bank.json.gz" in absent.join["note"]
    other = seed_results(frame.assign(bank_sha256="x"), bank, "bank.json")
    assert other.join["status"] == "no_rows_on_this_bank" and not other.ok


def test_family_hashes_have_the_manifest_shape(study):
    _, bank, _ = study
    assert family_hashes(bank.data)["highway"] == {"ours": {"7": "ours7", "8": "ours8",
                                                           "9": "ours9"},
                                                  "vae": {"3": "vae3", "4": "vae4"}}


def test_verdicts_need_significance_and_take_the_sign():
    got = verdicts([-0.1, 0.1, -0.1, 0.2], [0.001, 0.001, 0.2, float("nan")], alpha=0.01)
    assert got.tolist() == ["ours", "vae", "neither", "neither"]
    named = verdicts([-0.1, 0.1, 0.0, 0.1, -0.1], [0.001, 0.001, 0.001, 0.5, float("nan")],
                     alpha=0.01, a=pd.Series(["cv", "cv", "cv", "ours", "cv"]), b="ctrv")
    assert named.tolist() == ["cv", "ctrv", "neither", "neither", "neither"]


def test_verdict_counts_per_world():
    table = pd.DataFrame({"world": ["a", "a", "a", "b"],
                          "verdict": ["ours", "ours", "neither", "vae"]})
    assert verdict_counts(table) == {"a": {"ours": 2, "vae": 0, "neither": 1},
                                     "b": {"ours": 0, "vae": 1, "neither": 0}}


def test_arms_split_the_rows_and_pool_them():
    rows = add_alignment_errors(fixed_predictions(n_participants=5, trials=4))
    table = by_arm_table({"primary": rows}).set_index(["world", "arm", "answers"])
    for world in ("highway", "obstacle"):
        pooled = compare_per_world(rows.groupby(["participant_id", "world"])
                                   [["err_ours", "err_vae"]].mean().reset_index())[world]
        assert table.loc[(world, "pooled", "primary"), "t"] == pytest.approx(pooled.t)
        for arm, trials in (("random", (0, 2)), ("models_disagree", (1, 3))):
            ids = [f"{world}-{t}" for t in trials]
            sub = rows[rows["trial_id"].isin(ids)].groupby("participant_id")
            means = sub[["err_ours", "err_vae"]].mean()
            res = paired_comparison(means["err_ours"], means["err_vae"])
            row = table.loc[(world, arm, "primary")]
            assert row["n_trials"] == 2 and row["n"] == 5
            assert row["mean_diff"] == pytest.approx(res.mean_diff, rel=1e-12)
            assert row["p_two_sided"] == pytest.approx(res.p_two_sided, rel=1e-10)


def test_an_export_without_arms_is_only_pooled():
    rows = add_alignment_errors(fixed_predictions(n_participants=3)).assign(arm="")
    assert set(by_arm_table({"primary": rows})["arm"]) == {"pooled"}
