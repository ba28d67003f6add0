"""The direct test of the claim: people whose clicks follow the coarse observers, the precise
one or neither get that verdict, per variant and per world."""

import numpy as np
import pandas as pd
import pytest

from analysis.crossed import crossed_test
from analysis.direct import (
    COARSE_OBSERVERS,
    direct_summary,
    direct_table,
    observers_present,
    world_verdict,
)
from analysis.metrics import add_alignment_errors
from analysis.report import run_analyze
from app.core.contracts import plugin_columns
from tests.analysis.report_inputs import simulated_export

ALPHA = 0.01
# per coarse variant, how far (rad) it turns from the shared coarse direction
VARIANT_TURN = {"coarse": 0.0, "coarse_scene": 0.08, "coarse_momentum": -0.08}


def unit(angle: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def observer_rows(rng, people: str, n_people: int = 20, n_trials: int = 20, seen: int = 10,
                  steps: int = 3, world: str = "highway",
                  variants: tuple[str, ...] = COARSE_OBSERVERS) -> pd.DataFrame:
    """Kept rows of one world: per trial the precise observer's direction, the coarse one
    0.8 rad off it; people click near the coarse direction ('coarse'), the precise one
    ('precise') or anywhere ('random'), with 0.3 rad of click noise."""
    precise = rng.uniform(-np.pi, np.pi, n_trials)
    coarse = precise + rng.choice([-0.8, 0.8], n_trials)
    rows = []
    for p in range(n_people):
        for k in range(seen):
            trial = (p * seen + k) % n_trials
            for step in range(steps):
                aim = {"coarse": coarse[trial], "precise": precise[trial],
                       "random": rng.uniform(-np.pi, np.pi)}[people]
                row = {"world": world, "participant_id": f"p{p:02d}",
                       "trial_id": f"{world}-{trial:02d}", "step": step}
                clicked = unit(aim + rng.normal(0, 0.3))
                row |= dict(zip(("participant_vx", "participant_vy"), clicked, strict=True))
                row |= dict(zip(("policy_vx", "policy_vy"), unit(precise[trial]), strict=True))
                for name in variants:
                    move = unit(coarse[trial] + VARIANT_TURN[name])
                    row |= dict(zip(plugin_columns(name), (*move, -1, "s" * 64), strict=True))
                rows.append(row)
    return pd.DataFrame(rows)


def with_errors(frame: pd.DataFrame) -> pd.DataFrame:
    return add_alignment_errors(frame, ("policy", *observers_present(frame.columns)))


@pytest.mark.parametrize("people, verdict", [("coarse", "coarse"), ("precise", "precise"),
                                             ("random", "neither")])
def test_the_world_gets_the_verdict_of_the_observer_people_follow(people, verdict):
    kept = with_errors(observer_rows(np.random.default_rng(0), people))
    table = direct_table(kept, ALPHA, {})
    assert list(table["variant"]) == list(COARSE_OBSERVERS)
    assert set(table["verdict"]) == {verdict} and set(table["world_verdict"]) == {verdict}
    assert (table["p_holm"] >= table["p_two_sided"]).all()
    assert ((table["ci95_low"] < table["mean_diff"]) & (table["mean_diff"]
                                                       < table["ci95_high"])).all()


def test_a_variant_is_the_crossed_test_of_its_error_minus_the_precise_one():
    kept = with_errors(observer_rows(np.random.default_rng(1), "coarse"))
    row = direct_table(kept, ALPHA, {}).set_index("variant").loc["coarse_scene"]
    cells = (kept.assign(diff=kept["err_coarse_scene"] - kept["err_policy"])
             .groupby(["participant_id", "trial_id"])["diff"].mean().reset_index())
    expected = crossed_test(cells["diff"], cells["participant_id"], cells["trial_id"])
    assert row["mean_diff"] == pytest.approx(expected.mean_diff) and row["mean_diff"] < 0
    assert row["min_f"] == pytest.approx(expected.min_f)
    assert row["err_variant"] - row["err_precise"] == pytest.approx(row["mean_diff"])


def test_the_world_rule_needs_no_variant_worse_and_every_one_for_precise():
    assert world_verdict(["coarse", "neither", "neither"]) == "coarse"
    assert world_verdict(["coarse", "precise", "neither"]) == "neither"
    assert world_verdict(["precise", "precise", "precise"]) == "precise"
    assert world_verdict(["precise", "precise", "neither"]) == "neither"
    assert world_verdict(["neither"]) == "neither"


def test_holm_runs_over_the_variants_present():
    rng = np.random.default_rng(2)
    one = direct_table(with_errors(observer_rows(rng, "coarse", variants=("coarse",))), ALPHA,
                       {})
    assert list(one["variant"]) == ["coarse"]
    assert one["p_holm"].iloc[0] == pytest.approx(one["p_two_sided"].iloc[0])


def test_older_exports_and_unanswered_worlds_are_skipped():
    rng = np.random.default_rng(3)
    old = observer_rows(rng, "coarse", variants=())
    assert direct_table(with_errors(old), ALPHA, {}).empty
    both = pd.concat([observer_rows(rng, "coarse"),
                      observer_rows(rng, "coarse", world="obstacle")], ignore_index=True)
    both.loc[both["world"] == "obstacle", [c for n in COARSE_OBSERVERS
                                           for c in plugin_columns(n)[:2]]] = np.nan
    table = direct_table(with_errors(both), ALPHA, {"highway": "exploratory, for the test"})
    assert set(table["world"]) == {"highway"} and table["exploratory"].all()
    summary = direct_summary(table)
    assert list(summary) == ["highway"] and summary["highway"]["exploratory"] is True
    assert summary["highway"]["verdict"] == "coarse"
    assert list(summary["highway"]["variants"]) == list(COARSE_OBSERVERS)
    assert {"mean_diff", "ci95_low", "ci95_high", "p_holm", "verdict"} <= set(
        summary["highway"]["variants"]["coarse"])


def test_analyze_writes_the_direct_test_where_the_export_has_observers(tmp_path, capsys,
                                                                       inputs):
    frame = simulated_export("coarse", 10, seed=5)
    rng = np.random.default_rng(5)
    for name in COARSE_OBSERVERS:  # each observer: the policy's move, turned half a radian
        turn = 0.5 + rng.normal(0, 0.05, len(frame))
        vx, vy = frame["policy_vx"], frame["policy_vy"]
        frame = frame.assign(**dict(zip(plugin_columns(name), (
            vx * np.cos(turn) - vy * np.sin(turn), vx * np.sin(turn) + vy * np.cos(turn), -1,
            "o" * 64), strict=True)))
    frame.to_csv(tmp_path / "export.csv", index=False)
    summary = run_analyze("paper_study", tmp_path / "report", tmp_path / "export.csv", "",
                          inputs)
    table = pd.read_csv(tmp_path / "report" / "direct.csv")
    assert len(table) == 6 and set(table["world"]) == {"highway", "obstacle"}
    for entry in summary["direct"].values():  # people are nearer the policy than the turns
        assert list(entry["variants"]) == list(COARSE_OBSERVERS)
        assert all(v["mean_diff"] > 0 for v in entry["variants"].values())
        assert entry["verdict"] in ("precise", "neither") and entry["exploratory"] is False
    assert summary["direct"]["obstacle"]["verdict"] == "precise"  # six clips that all agree
    printed = capsys.readouterr().out
    assert printed.count("direct test (each coarse observer - the precise one") == 2
