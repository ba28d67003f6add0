"""The participant page driven by clicking: the steps every browser test walks the same way."""

import uuid

VIEWPORT = {"width": 1280, "height": 900}


def fresh_recruitment() -> str:
    """URL parameters of a new Prolific participant (each visit a new session)."""
    return f"PROLIFIC_PID={uuid.uuid4().hex[:24]}&STUDY_ID={'5' * 24}&SESSION_ID=s1"


def visible(page, screen: str) -> None:
    """Wait until the participant app shows `screen`."""
    page.wait_for_selector(f"#screen-{screen}:not([hidden])", timeout=15000)


def through_instructions(page) -> None:
    """Consent and instructions, by clicking."""
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    page.click("#instructions-done")
    visible(page, "trial")


def answer_survey(page) -> None:
    """Pick the first option of each closing question and finish."""
    visible(page, "survey")
    for name in sorted(set(page.eval_on_selector_all("#survey-form input[type=radio]",
                                                     "els => els.map(e => e.name)"))):
        page.check(f"#survey-form input[name={name}] >> nth=0")
    page.click("#survey-form button[type=submit]")
