"""The study's answer in words: one sentence per world, shared by report.html's first page,
`tomstudy analyze`'s printout and the researcher dashboard.

`primary_sentence` reads one world's entry of summary["primary"] (the pre-registered test:
the model family, participants and trials random, min F'). An entry with a `conclusion`
(ours, vae, equivalent, inconclusive, any case: the difference test and the equivalence test within
the smallest effect size of interest, SESOI) is said as such, with its 95% CI; an entry
without one has only the two-sided verdict (ours, vae, neither) and is said with its p,
never as equivalence. `direct_sentence` reads one world's entry of summary["direct"] (do
people align better with coarse observers than with a precise one).
"""

import math

EXPLORATORY = "EXPLORATORY — not a test of the hypothesis"
# summary["primary"] holds each world's entry and, under this key, the exploratory worlds
EXPLORATORY_KEY = "exploratory_worlds"
CLAIMS = {  # by conclusion, in lower case (primary_table writes ours, vae, equivalent, ...)
    "ours": "people's predictions align better with Ours than with the VAE",
    "vae": "people's predictions align better with the VAE than with Ours",
    "equivalent": "the two models are equivalent within ±{sesoi}",
    "inconclusive": "inconclusive: neither a difference nor equivalence could be shown",
}
# an entry without `conclusion`: the two-sided difference test alone (no equivalence test)
TWO_SIDED = ("ours", "vae")
NO_DIFFERENCE = "no difference between the two models could be shown; equivalence was not tested"
DIRECT_CLAIMS = {
    "coarse": "people's predictions align better with the coarse observers than with the "
              "precise one",
    "precise": "people's predictions align better with the precise observer than with the "
               "coarse ones",
    "neither": "neither the coarse observers nor the precise one align better with people's "
               "predictions",
}


def fmt(value, digits: int = 3) -> str:
    """A report number: fixed digits, tiny values in short g form, None or NaN as '-'."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1e-3 and value != 0 else f"{value:.{digits}f}"
    return str(value)


def fmt_p(value) -> str:
    """A p value to two significant digits (0.033, 4.1e-05), None or NaN as '-'."""
    return fmt(value) if not _finite(value) else f"{value:.2g}"


def world_label(world: str, exploratory: bool) -> str:
    """'Highway', or 'Obstacle (EXPLORATORY — not a test of the hypothesis)'."""
    name = world[:1].upper() + world[1:]
    return f"{name} ({EXPLORATORY})" if exploratory else name


def claim(entry: dict) -> str:
    """What the primary test concludes, in words (without the numbers)."""
    if "conclusion" in entry:
        text = CLAIMS.get(str(entry["conclusion"]).lower(), f"conclusion {entry['conclusion']}")
        sesoi = entry.get("sesoi")
        return text.format(sesoi=fmt(sesoi) if _finite(sesoi) else "the smallest effect of "
                           "interest")
    verdict = entry.get("verdict")
    return CLAIMS[verdict] if verdict in TWO_SIDED else NO_DIFFERENCE


def estimate(entry: dict) -> str:
    """The Ours - VAE difference in alignment error with its 95% CI (or, without one, its
    two-sided p), and how many participants and trials it rests on."""
    text = f"Ours - VAE alignment error {fmt(entry.get('mean_diff'))}"
    low, high = entry.get("ci95_low"), entry.get("ci95_high")
    if _finite(low) and _finite(high):
        text += f", 95% CI [{fmt(low)}, {fmt(high)}]"
    elif "p_two_sided" in entry:
        text += f", two-sided p = {fmt_p(entry['p_two_sided'])}"
    return (f"{text}; {entry.get('n_participants', '?')} participants, "
            f"{entry.get('n_trials', '?')} trials")


def primary_sentence(world: str, entry: dict) -> str:
    """One world's answer under the pre-registered primary test, as one sentence."""
    label = world_label(world, bool(entry.get("exploratory")))
    return f"{label}: {claim(entry)} ({estimate(entry)})."


def primary_sentences(primary: dict) -> dict[str, str]:
    """primary_sentence of every world of summary["primary"], in its order."""
    return {world: primary_sentence(world, entry) for world, entry in primary.items()
            if world != EXPLORATORY_KEY}


def direct_sentence(world: str, entry: dict) -> str:
    """One world's answer to the direct test (coarse observers vs a precise one), with each
    coarse variant's difference, 95% CI and Holm-adjusted p."""
    label = world_label(world, bool(entry.get("exploratory")))
    text = DIRECT_CLAIMS.get(entry.get("verdict"), f"verdict {entry.get('verdict')}")
    variants = "; ".join(
        f"{name} {fmt(v.get('mean_diff'))}, 95% CI [{fmt(v.get('ci95_low'))}, "
        f"{fmt(v.get('ci95_high'))}], Holm p = {fmt_p(v.get('p_holm'))}"
        for name, v in (entry.get("variants") or {}).items())
    return f"{label}, direct test: {text}" + (f" ({variants})." if variants else ".")


def direct_sentences(direct: dict) -> dict[str, str]:
    """direct_sentence of every world of summary["direct"]."""
    return {world: direct_sentence(world, entry) for world, entry in direct.items()
            if isinstance(entry, dict)}


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)
