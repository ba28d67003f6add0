"""What a participant is told before agreeing: the consent page's sections and the study's
description, with the time and pay rendered from the estimate (app/study/estimate.py), and the
check that keeps a form with a lab's [PLACEHOLDER] off a production server."""

import re
from dataclasses import dataclass

from app.study.config import PLACEHOLDER, ConsentForm, StudyConfig

# a hand-typed duration in a text a participant reads ("About 25 minutes")
TYPED_TIME = r"\b\d+\s*(?:-\s*\d+\s*)?(?:minutes?|mins?)\b"
PLATFORM_NAMES = {"prolific": "Prolific", "mturk": "MTurk", "open": "the lab"}


@dataclass(frozen=True)
class Advert:
    """The time and pay a study states: the median participant's estimate, rounded up."""

    minutes: int
    pay: str  # e.g. "GBP 5.85", or "" when the study sets no hourly pay
    hourly: str  # e.g. "GBP 9.00 per hour", or ""
    pay_amount: float = 0.0  # the pay as a number (0 without an hourly pay)
    currency: str = ""

    def duration(self) -> str:
        """The time as a participant reads it."""
        return f"about {self.minutes} minutes"


def money(amount: float, currency: str) -> str:
    """An amount with its currency, to the cent."""
    return f"{currency} {amount:.2f}"


def render(text: str, advert: Advert) -> str:
    """`text` with {duration} and {pay} filled in from the advert."""
    return text.replace("{duration}", advert.duration()).replace("{pay}", advert.pay)


def time_and_pay(config: StudyConfig, advert: Advert) -> str:
    """The consent section on time and payment."""
    platform = PLATFORM_NAMES[config.recruitment.platform]
    text = (f"The study takes {advert.duration()} (our estimate for a participant reading and "
            f"clicking at a steady pace; there is no time limit).")
    if advert.pay:
        text += (f" You will be paid {advert.pay} ({advert.hourly}) through {platform} when "
                 f"you finish.")
    return text


def investigators_text(form: ConsentForm) -> str:
    """Who runs the study and how to reach them, one line each."""
    lines = [f"{p.name}{f' ({p.role})' if p.role else ''}, {p.email}" for p in form.investigators]
    return "\n\n".join([f"This study is run by {form.institution}.", *lines])


def consent_sections(config: StudyConfig, advert: Advert) -> list[dict]:
    """The consent page in order: heading and text of each section (none for a study that
    still uses the free `consent_text`)."""
    form = config.consent
    if form is None:
        return []
    parts = [("What this study is", form.purpose),
             ("Who is running it", investigators_text(form)),
             ("Ethics approval", form.ethics_approval),
             ("Time and payment", time_and_pay(config, advert)),
             ("What we record", form.recorded),
             ("How long we keep your data and who sees it", form.retention),
             ("Taking part is voluntary", form.voluntary),
             ("Stopping and withdrawing", form.withdrawal),
             ("Risks and benefits", form.risks)]
    return [{"heading": h, "text": render(t, advert)} for h, t in parts]


def consent_words(config: StudyConfig, advert: Advert) -> int:
    """Words on the consent page (the free text, or every section with its heading)."""
    sections = consent_sections(config, advert)
    if not sections:
        return len(render(config.consent_text, advert).split())
    return sum(len(f"{s['heading']} {s['text']}".split()) for s in sections)


def consent_fields(config: StudyConfig) -> list[tuple[str, str]]:
    """(field path, text) of every consent field and the description, as the config names
    them."""
    fields = [("description", config.description)]
    form = config.consent
    if form is None:
        return fields + [("consent_text", config.consent_text)]
    for name in ConsentForm.model_fields:
        if name != "investigators":
            fields.append((f"consent.{name}", getattr(form, name)))
    for i, person in enumerate(form.investigators):
        fields += [(f"consent.investigators.{i}.{key}", getattr(person, key))
                   for key in ("name", "role", "email")]
    return fields


def consent_problem(config: StudyConfig, production: bool) -> str | None:
    """Why the study's consent cannot be shown, or None: {pay} without an hourly pay, and in
    production a [PLACEHOLDER], a hand-typed time or no typed consent form at all."""
    fields = consent_fields(config)
    for name, text in fields:
        if "{pay}" in text and config.recruitment.hourly_pay is None:
            return f"{name}: uses {{pay}} but recruitment.hourly_pay is not set"
    if not production:
        return None
    if config.consent is None:
        return ("consent: a production study needs the typed consent form (institution, "
                "investigators, ethics approval...), not only consent_text")
    for name, text in fields:
        if found := re.search(PLACEHOLDER, text):
            return f"{name}: still holds the placeholder {found.group(0)}; write your own"
        if found := re.search(TYPED_TIME, text, flags=re.IGNORECASE):
            return (f"{name}: states the time by hand ({found.group(0)!r}); write {{duration}} "
                    "so it follows the estimate")
    return None
