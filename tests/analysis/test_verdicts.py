"""The answer in words: one sentence per world for each conclusion, in both summary shapes."""

import pytest

from analysis.verdicts import (
    EXPLORATORY,
    direct_sentence,
    direct_sentences,
    primary_sentence,
    primary_sentences,
)

# summary["primary"][world] as primary_table writes it today (two-sided verdict only)
OLD = {"mean_diff": -0.0412, "n_participants": 22, "n_trials": 40, "t_participants": -3.1,
       "t_trials": -2.8, "min_f": 4.9, "df": 38.2, "p_two_sided": 0.0329, "verdict": "ours",
       "exploratory": False}
# ... and with the equivalence test's keys
NEW = OLD | {"ci95_low": -0.0801, "ci95_high": -0.0023, "sesoi": 0.05, "tost_p": 0.4,
             "bf10": 3.2, "conclusion": "ours"}


@pytest.mark.parametrize(("conclusion", "words"), [
    ("ours", "Highway: people's predictions align better with Ours than with the VAE ("),
    ("Ours", "Highway: people's predictions align better with Ours than with the VAE ("),
    ("vae", "Highway: people's predictions align better with the VAE than with Ours ("),
    ("VAE", "Highway: people's predictions align better with the VAE than with Ours ("),
    ("equivalent", "Highway: the two models are equivalent within ±0.050 ("),
    ("inconclusive", "Highway: inconclusive: neither a difference nor equivalence could be "
                     "shown ("),
])
def test_each_conclusion_is_one_sentence_with_its_ci_and_counts(conclusion, words):
    sentence = primary_sentence("highway", NEW | {"conclusion": conclusion})
    assert sentence.startswith(words)
    assert sentence.endswith("(Ours - VAE alignment error -0.041, 95% CI [-0.080, -0.002]; "
                             "22 participants, 40 trials).")
    assert EXPLORATORY not in sentence and "p =" not in sentence


@pytest.mark.parametrize(("verdict", "words"), [
    ("ours", "people's predictions align better with Ours than with the VAE"),
    ("vae", "people's predictions align better with the VAE than with Ours"),
    ("neither", "no difference between the two models could be shown; equivalence was not "
                "tested"),
])
def test_without_the_new_keys_the_two_sided_verdict_is_said_with_its_p(verdict, words):
    sentence = primary_sentence("highway", OLD | {"verdict": verdict})
    assert sentence == (f"Highway: {words} (Ours - VAE alignment error -0.041, two-sided "
                        "p = 0.033; 22 participants, 40 trials).")
    assert "CI" not in sentence and "equivalent" not in sentence


def test_an_exploratory_world_says_so_and_a_missing_ci_or_sesoi_degrades():
    entry = NEW | {"exploratory": True, "conclusion": "equivalent", "sesoi": None,
                   "ci95_low": None}
    sentence = primary_sentence("obstacle", entry)
    assert sentence.startswith(f"Obstacle ({EXPLORATORY}): the two models are equivalent "
                               "within ±the smallest effect of interest (")
    assert "CI" not in sentence and "two-sided p = 0.033" in sentence


def test_primary_sentences_skip_the_exploratory_worlds_entry():
    primary = {"highway": NEW, "obstacle": OLD | {"exploratory": True},
               "exploratory_worlds": {"obstacle": "its design cannot meet the goal"}}
    sentences = primary_sentences(primary)
    assert list(sentences) == ["highway", "obstacle"]
    assert EXPLORATORY in sentences["obstacle"] and EXPLORATORY not in sentences["highway"]


def test_direct_sentence_names_the_verdict_and_each_variant():
    variant = {"mean_diff": -0.03, "ci95_low": -0.05, "ci95_high": -0.01, "p_holm": 0.004,
               "verdict": "coarse"}
    entry = {"variants": {"coarse_scene": variant, "coarse_momentum": variant},
             "verdict": "coarse", "exploratory": False}
    sentence = direct_sentence("highway", entry)
    assert sentence.startswith("Highway, direct test: people's predictions align better with "
                               "the coarse observers than with the precise one (coarse_scene "
                               "-0.030, 95% CI [-0.050, -0.010], Holm p = 0.004; coarse_momentum")
    for verdict, words in (("precise", "better with the precise observer"),
                           ("neither", "neither the coarse observers nor the precise one")):
        assert words in direct_sentence("highway", entry | {"verdict": verdict})
    assert EXPLORATORY in direct_sentences({"obstacle": entry | {"exploratory": True}})[
        "obstacle"]
