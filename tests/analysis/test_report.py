"""`analyze` writes a self-contained report whose numbers match the per-participant table."""

import html as html_text
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.metrics import add_alignment_errors
from analysis.report import (
    AnalysisError,
    render_html,
    run_analyze,
    smallest_effect,
    start_kind_table,
)
from analysis.verdicts import EXPLORATORY, direct_sentence, primary_sentence
from app.core.contracts import SMALLEST_EFFECT_OF_INTEREST, StudyInputs
from tests.analysis.fixed_data import fixed_predictions
from tests.analysis.report_inputs import BANK_SHA, MODELS, RULES, simulated_export


def test_report_from_csv(tmp_path, inputs, capsys):
    frame = simulated_export("coarse", 12, seed=3)
    frame.loc[frame["participant_id"] == "sim-00001", "completed"] = False
    frame.loc[frame["participant_id"] == "sim-00002", "bank_sha256"] = "e" * 64
    frame.to_csv(tmp_path / "export.csv", index=False)
    out = tmp_path / "report"
    summary = run_analyze("paper_study", out, tmp_path / "export.csv", "", inputs)
    for name in ("report.html", "summary.json", "per_participant.csv", "meta.json",
                 "alignment_error.png", "alignment_error.svg", "fields_highway.png",
                 "fields_obstacle.svg", "per_seed.csv", "family.csv", "by_arm.csv",
                 "mixed_model.csv", "leave_one_trial_out.csv", "seed_pairs.png",
                 "leave_one_trial_out.svg"):
        assert (out / name).is_file(), name
    assert summary["exclusions"]["excluded_incomplete"] == 1
    table = pd.read_csv(out / "per_participant.csv")
    assert table["participant_id"].nunique() == 11
    for world, res in summary["ours_vs_vae"].items():
        rows = table[table["world"] == world]
        assert res["n"] == len(rows) == 11
        assert res["mean_a"] == pytest.approx(rows["err_ours"].mean())
        assert summary["worlds"][world]["err_vae"]["mean"] == pytest.approx(rows["err_vae"].mean())
    html = (out / "report.html").read_text()
    assert "data:image/png;base64," in html and "src='http" not in html
    meta = json.loads((out / "meta.json").read_text())
    assert meta["trial_bank_sha256"] == BANK_SHA and len(meta["data_sha256"]) == 64
    assert meta["models"] == MODELS and meta["models_match_bank"] is True
    assert meta["study_config"] == inputs.config

    assert "start_kind" in pd.read_csv(tmp_path / "export.csv").columns
    kinds = pd.read_csv(out / "by_start_kind.csv")
    assert list(kinds.columns[:3]) == ["world", "start_kind", "n"]
    assert list(kinds[kinds["world"] == "highway"]["start_kind"]) == [
        "own", "same_lane", "adjacent_lane"]
    assert list(kinds[kinds["world"] == "obstacle"]["start_kind"]) == ["own", "near", "mid"]
    assert (kinds["n"] == 11).all()
    kept = add_alignment_errors(frame[frame["participant_id"] != "sim-00001"])
    for row in kinds.itertuples():
        rows = kept[(kept["world"] == row.world) & (kept["start_kind"] == row.start_kind)]
        per_person = rows.groupby("participant_id")[["err_ours", "err_vae"]].mean()
        assert row.err_ours == pytest.approx(per_person["err_ours"].mean())
        assert row.mean_diff == pytest.approx((per_person["err_ours"]
                                               - per_person["err_vae"]).mean())
        assert summary["by_start_kind"][row.world][row.start_kind]["n"] == 11
    assert "adjacent_lane" in html and "By start kind" in html

    # every seed's answers: sim-00002 ran another bank, is left out of them, and it is said
    seeds = summary["seeds"]
    assert seeds["participants_other_bank"] == ["sim-00002"] and "left out" in seeds["note"]
    assert seeds["primary_max_abs_diff"] < 1e-9  # the bank's primary seed is the export's
    per_seed = pd.read_csv(out / "per_seed.csv")
    family = pd.read_csv(out / "family.csv").set_index("world")
    on_bank = kept[kept["participant_id"] != "sim-00002"]
    for world in ("highway", "obstacle"):
        pairs = per_seed[per_seed["world"] == world].set_index("pair")
        assert list(pairs.index) == [0, 1, 2] and (pairs["n"] == 10).all()
        people = on_bank[on_bank["world"] == world].groupby("participant_id")
        primary = (people["err_ours"].mean() - people["err_vae"].mean()).mean()
        assert pairs.loc[0, "mean_diff"] == pytest.approx(primary, rel=1e-9)
        # equal families: the family's mean error is the mean of the pairs'
        assert family.loc[world, "err_ours"] == pytest.approx(pairs["err_ours"].mean())
        assert family.loc[world, "n"] == 10
        counts = summary["seed_pair_verdicts"][world]
        assert sum(counts.values()) == 3
        assert counts[summary["family"][world]["verdict"]] >= 1
        arms = summary["by_arm"][world]
        assert list(arms) == ["pooled", "models_disagree", "random"]
        assert arms["pooled"]["primary"]["n"] == 11 and arms["pooled"]["family"]["n"] == 10
        mixed = summary["mixed_model"][world]["pooled"]["primary"]
        assert mixed["status"] in ("ok", "boundary") and mixed["n_participants"] == 11
        assert summary["leave_one_trial_out"][world]["family"]["most_influential"]["trial_id"]
        primary_test = summary["primary"][world]  # the family, participants and trials random
        assert primary_test["n_participants"] == 10 and primary_test["verdict"] in (
            "ours", "vae", "neither")
        assert primary_test["mean_diff"] == pytest.approx(family.loc[world, "mean_diff"],
                                                          abs=0.02)
        assert primary_test["sesoi"] == 0.005  # the config's default (it sets none)
        assert primary_test["ci95_low"] < primary_test["mean_diff"] < primary_test["ci95_high"]
        assert 0 <= primary_test["tost_p"] <= 1 and primary_test["bf10"] > 0
        assert primary_test["conclusion"] == (primary_test["verdict"] if primary_test[
            "verdict"] != "neither" else "equivalent" if primary_test["tost_p"] < 0.01
            else "inconclusive")
    assert summary["primary"]["exploratory_worlds"] == {}
    assert (out / "primary.csv").is_file() and "pre-registered primary test in numbers" in html
    assert list(pd.read_csv(out / "primary.csv").columns[-6:]) == [
        "ci95_low", "ci95_high", "sesoi", "tost_p", "bf10", "conclusion"]
    ceiling = summary["noise_ceiling"]  # coarse bots agree far more than chance
    assert set(ceiling) == {"highway", "obstacle"} and "Human noise ceiling" in html
    for entry in ceiling.values():
        assert 0 <= entry["upper"] <= entry["lower"] < 1
        assert {"ours", "vae", "cv", "policy"} <= set(entry["share"])  # and any observer
    influence = pd.read_csv(out / "leave_one_trial_out.csv")
    trials = kept.groupby("world")["trial_id"].nunique().sum()
    assert len(influence) == 2 * trials  # each main trial, for primary and family answers
    for section in ("Model families", "By selection arm", "crossed mixed model",
                    "Leave-one-trial-out"):
        assert section in html
    printed = capsys.readouterr().out
    assert "family (3 Ours x 3 VAE seeds)" in printed and "trials as random" in printed
    assert "highway (primary): family Ours - VAE" in printed
    assert "within +-0.005: TOST p = " in printed and "BF10 = " in printed
    assert printed.startswith(primary_sentence("highway", summary["primary"]["highway"]) + "\n")
    assert "noise ceiling (people predicting each other)" in printed
    assert "1 participant(s)) ran another bank" in printed
    first_page_answers(html, summary)
    every_figure_captioned(html, summary)
    equivalence_and_direct_test_on_the_first_page(summary, out)


def sections(html: str) -> tuple[str, str]:
    """The report's first section (the answer) and everything from Details on."""
    answer = re.search(r'<section class="answer" id="answer" aria-labelledby="answer-heading">'
                       r'(.*?)</section>', html, re.S)
    assert answer, "no answer section"
    details = html.index('<section id="details" aria-labelledby="details-heading">')
    assert answer.end() <= details
    return answer.group(1), html[details:]


def first_page_answers(html: str, summary: dict) -> None:
    """The first section says each world's primary verdict in words, then the ceiling
    figure; the first table of the page comes after it, under Details."""
    answer, details = sections(html)
    assert "<table" not in html[:html.index('<section id="details"')]
    lines = re.findall(r'<li data-world="(\w+)">(.*?)</li>', answer, re.S)
    worlds = [w for w in summary["primary"] if w != "exploratory_worlds"]
    assert [w for w, _ in lines] == worlds == ["highway", "obstacle"]
    for world, line in lines:
        assert html_text.unescape(line) == primary_sentence(world, summary["primary"][world])
        verdict = summary["primary"][world]["verdict"]
        said = {"ours": "align better with Ours than with the VAE",
                "vae": "align better with the VAE than with Ours",
                "neither": "no difference between the two models could be shown"}[verdict]
        assert said in html_text.unescape(line)
    assert answer.index("</ul>") < answer.index("<figure>")  # verdicts, then the figure
    assert "noise ceiling" in html_text.unescape(answer) and "<table" in details
    assert "<p>Details" not in answer and details.index("<h2 id=\"details-heading\">") < 80


def every_figure_captioned(html: str, summary: dict) -> None:
    """Each figure has a caption in words (what is plotted, what lower means), never its
    file name, and the ceiling figure is among them."""
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", html, re.S)
    pngs = [name for name in summary["figures"] if name.endswith(".png")]
    assert "noise_ceiling.png" in pngs and len(captions) == len(pngs)
    for caption in captions:
        assert not re.search(r"\.(png|svg)\b", caption) and len(caption) > 120
        assert re.search(r"lower|below 0|left of 0", caption, re.I), caption
    assert "<th>p &lt; 0.01</th>" not in html  # the one-sided column says which test it is
    assert "Ours &lt; VAE at one-sided p &lt; 0.01" in html


def equivalence_and_direct_test_on_the_first_page(summary: dict, out: Path) -> None:
    """A summary with the equivalence test's keys and the direct test renders both sentences
    (the exploratory world's too) and their columns."""
    equivalence = {"ci95_low": -0.5, "ci95_high": -0.2, "sesoi": 0.05, "tost_p": 0.9,
                   "bf10": 12.0}
    summary["primary"]["highway"] |= equivalence | {"conclusion": "ours"}
    summary["primary"]["obstacle"] |= equivalence | {"conclusion": "inconclusive",
                                                     "exploratory": True}
    variant = {"mean_diff": -0.03, "ci95_low": -0.05, "ci95_high": -0.01, "p_holm": 0.004,
               "verdict": "coarse"}
    summary["direct"] = {"highway": {"variants": {"coarse_scene": variant},
                                     "verdict": "coarse", "exploratory": False}}
    page = render_html(summary, sorted(out.glob("*.png")))
    answer, details = sections(page)
    answer = html_text.unescape(answer)
    assert ("Highway: people's predictions align better with Ours than with the VAE (Ours - "
            "VAE alignment error") in answer and "95% CI [-0.500, -0.200]" in answer
    assert f"Obstacle ({EXPLORATORY}): inconclusive: neither a difference" in answer
    assert direct_sentence("highway", summary["direct"]["highway"]) in answer
    assert answer.index("direct test") > answer.index("Obstacle (")
    assert "TOST p (equivalence, two one-sided tests)" in details
    assert "coarse_scene" in details


def test_the_smallest_effect_comes_from_the_config_or_its_default():
    assert smallest_effect({}) == SMALLEST_EFFECT_OF_INTEREST
    assert smallest_effect({"smallest_effect_of_interest": 0.02}) == 0.02


def test_without_a_bank_the_report_says_so_and_keeps_the_rest(tmp_path):
    fixed_predictions(n_participants=3).to_csv(tmp_path / "export.csv", index=False)
    inputs = StudyInputs(config={}, rules=RULES, models={}, bank=tmp_path / "absent.json.gz")
    out = tmp_path / "report"
    summary = run_analyze("paper_study", out, tmp_path / "export.csv", "", inputs)
    assert summary["seeds"]["status"] == "no_bank" and summary["family"] == {}
    assert not (out / "per_seed.csv").exists() and (out / "mixed_model.csv").is_file()
    assert list(summary["by_arm"]["highway"]["pooled"]) == ["primary"]
    assert "no trial bank at" in (out / "report.html").read_text()
    meta = json.loads((out / "meta.json").read_text())
    assert meta["trial_bank_sha256"] is None and meta["models_match_bank"] is None


def test_start_kind_table_with_one_participant_has_no_test():
    rows = add_alignment_errors(fixed_predictions(n_participants=3, starts=2))
    rows = rows[(rows["start_kind"] == "own") | (rows["participant_id"] == "p00")]
    table = start_kind_table(rows).set_index(["world", "start_kind"])
    assert table.loc[("highway", "own"), "n"] == 3
    assert np.isfinite(table.loc[("highway", "own"), "t"])
    one = table.loc[("highway", "same_lane")]
    assert one["n"] == 1 and np.isnan(one["t"]) and np.isfinite(one["mean_diff"])


def test_all_excluded_is_a_clear_error_and_waive_is_reported(tmp_path, inputs):
    frame = simulated_export("random", 6, seed=4)
    frame["attention_passed"] = False
    frame.to_csv(tmp_path / "export.csv", index=False)
    with pytest.raises(AnalysisError, match="every participant was excluded"):
        run_analyze("paper_study", tmp_path / "r1", tmp_path / "export.csv", "", inputs)
    summary = run_analyze("paper_study", tmp_path / "r2", tmp_path / "export.csv", "", inputs,
                          waive=("failed_attention_check",))
    assert summary["waived_rules"] == ["failed_attention_check"]
    assert summary["exclusions"]["participants_kept"] == 6
    with pytest.raises(AnalysisError, match="waive: unknown"):
        run_analyze("paper_study", tmp_path / "r3", tmp_path / "export.csv", "", inputs,
                    waive=("attention",))
