"""The consent page in chromium: a production server (`tomstudy serve` with
TOMSTUDY_PRODUCTION=1) shows every typed section of a filled-in form, the estimate's time and
pay, and each investigator's address as a link; a screenshot is saved for a person to look at.
The shipped placeholders keep the same server from starting."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from app.study.consent import PLATFORM_NAMES
from tests.conftest import (
    FILLED_CONSENT,
    REPO,
    TOMSTUDY,
    SmallStudy,
    free_port,
    patience,
    start_server,
)
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import SCREENSHOTS, VIEWPORT, fresh_recruitment, visible

PRODUCTION_ENV = {"TOMSTUDY_PRODUCTION": "1", "TOMSTUDY_ADMIN_TOKEN": "p" * 40,
                  "TOMSTUDY_RATE_LIMIT_STARTS": "100/minute",
                  "TOMSTUDY_RATE_LIMIT_REQUESTS": "10000/minute"}
HEADINGS = ["What this study is", "Who is running it", "Ethics approval", "Time and payment",
            "What we record", "How long we keep your data and who sees it",
            "Taking part is voluntary", "Stopping and withdrawing", "Risks and benefits"]


def with_configs(study: SmallStudy, root: Path, consent: dict) -> SmallStudy:
    """The browser study's data (its built bundle) with its config's consent form replaced."""
    configs = root / "configs"
    shutil.copytree(study.configs_dir, configs)
    path = configs / f"{BROWSER_STUDY}.yaml"
    path.write_text(yaml.safe_dump(yaml.safe_load(path.read_text()) | {"consent": consent}))
    return SmallStudy(study.data_dir, configs, BROWSER_STUDY)


@pytest.fixture(scope="module")
def filled_server(browser_study, tmp_path_factory):
    """A production server of the browser study with a filled-in consent form."""
    root = tmp_path_factory.mktemp("consent")
    study = with_configs(browser_study, root, FILLED_CONSENT)
    proc = start_server(study, f"sqlite:///{root / 'study.db'}", port := free_port(),
                        log=root / "server.log", **PRODUCTION_ENV)
    yield f"http://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(timeout=patience(10))


def test_the_consent_page_shows_every_section_of_the_form(chromium, filled_server):
    page = chromium.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"{filled_server}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    visible(page, "consent")
    form = page.locator("#consent-text")
    assert form.locator("h3").all_inner_texts() == HEADINGS
    text = form.inner_text()
    for field in ("institution", "ethics_approval", "purpose", "recorded", "retention",
                  "voluntary", "withdrawal", "risks"):
        assert FILLED_CONSENT[field] in text, field
    for person in FILLED_CONSENT["investigators"]:
        assert f"{person['name']} ({person['role']})" in text
        assert form.locator(f'a[href="mailto:{person["email"]}"]').inner_text() == person["email"]
    assert re.search(r"The study takes about \d+ minutes .* You will be paid GBP \d+\.\d\d "
                     rf"\(GBP 9\.00 per hour\) through {PLATFORM_NAMES['prolific']}", text)
    assert "[" not in text  # no placeholder left
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / "consent.png"), full_page=True)
    assert errors == []
    page.close()


def test_production_refuses_to_start_with_the_shipped_placeholders(browser_study, tmp_path):
    """The browser study's form is the paper study's as shipped: placeholders throughout."""
    env = browser_study.env(f"sqlite:///{tmp_path / 'p.db'}", **PRODUCTION_ENV)
    run = subprocess.run([TOMSTUDY, "serve", "--host", "127.0.0.1", "--port", str(free_port()),
                          "--study", BROWSER_STUDY], env=env, capture_output=True, text=True,
                         timeout=patience(120), cwd=REPO)
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr == (f"error: refusing to serve study {BROWSER_STUDY} in production mode: "
                          "consent.institution: still holds the placeholder [YOUR INSTITUTION]; "
                          "write your own\n")
