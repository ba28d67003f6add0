"""Browser-test fixtures: the paper's study (20 trials) on the small pipeline's models; chromium."""

import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from tests.conftest import (
    REPO,
    SMALL_SEEDS,
    SmallStudy,
    build_bundle_of,
    free_port,
    patience,
    start_server,
)

BROWSER_STUDY = "browser_study"
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
# The paper's study as written (2 worlds x 10 trials, 1 attention check per world, 1 practice),
# with a bank just large enough for one participant, so the small pipeline's data suffice
# (its main trials the first usable segments: the small data hold too few for 3 candidates each).
BANK_TRIALS_PER_WORLD = 10


@pytest.fixture(scope="session")
def browser_study(small_study: SmallStudy, tmp_path_factory) -> SmallStudy:
    """A copy of the small study's data and configs with the paper's study and its own bank."""
    root = tmp_path_factory.mktemp("browser-study")
    data_dir, configs_dir = root / "var", root / "configs"
    shutil.copytree(small_study.configs_dir, configs_dir)
    shutil.copytree(small_study.data_dir, data_dir,
                    ignore=shutil.ignore_patterns("trials", "bundles"))
    study = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    study["bank_trials_per_world"] = BANK_TRIALS_PER_WORLD
    study["main_trial_selection"] = {"rule": "random", "candidates_per_trial": 1}
    study |= {"models": {"seeds": SMALL_SEEDS}, "bundle": "built"}
    (configs_dir / f"{BROWSER_STUDY}.yaml").write_text(yaml.safe_dump(study))
    browser = SmallStudy(data_dir, configs_dir, BROWSER_STUDY)
    build_bundle_of(browser)
    return browser


@dataclass(frozen=True)
class BrowserServer:
    """A running server of the browser study and the SQLite file it writes."""

    url: str
    db_path: Path


def serve_study(study: SmallStudy, root: Path):
    """`tomstudy serve` of `study` on a fresh SQLite file under `root`, for a fixture's life."""
    port = free_port()
    db_path = root / "study.db"
    proc = start_server(study, f"sqlite:///{db_path}", port, log=root / "server.log")
    yield BrowserServer(f"http://127.0.0.1:{port}", db_path)
    proc.terminate()
    proc.wait(timeout=patience(10))


@pytest.fixture(scope="session")
def browser_server(browser_study: SmallStudy, tmp_path_factory):
    """`tomstudy serve` of the browser study on a fresh SQLite file."""
    yield from serve_study(browser_study, tmp_path_factory.mktemp("browser-server"))


@pytest.fixture(scope="session")
def interaction_server(interaction_study: SmallStudy, tmp_path_factory):
    """`tomstudy serve` of the interaction study (generated recordings) on a fresh SQLite file."""
    yield from serve_study(interaction_study, tmp_path_factory.mktemp("interaction-server"))


@pytest.fixture(scope="module")
def chromium():
    """Debian's chromium driven by Playwright (never a downloaded browser).

    Module scope: Playwright's sync API keeps an event loop running in the main thread
    while it is open, which would break later tests that call asyncio.run()."""
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is absent: install Debian's chromium (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield PatientBrowser(browser)
        browser.close()


class PatientBrowser:
    """A Playwright Browser whose contexts, pages and `expect`s wait as long as patience()
    allows (Playwright's own defaults: 30 s for actions, 5 s for `expect`)."""

    def __init__(self, browser):
        self._browser = browser

    def __getattr__(self, name: str):
        return getattr(self._browser, name)

    def new_context(self, **options):
        """Browser.new_context with the scaled default timeout."""
        context = self._browser.new_context(**options)
        context.set_default_timeout(self._patient_defaults())
        return context

    def new_page(self, **options):
        """Browser.new_page with the scaled default timeout."""
        page = self._browser.new_page(**options)
        page.set_default_timeout(self._patient_defaults())
        return page

    @staticmethod
    def _patient_defaults() -> float:
        from playwright.sync_api import expect

        expect.set_options(timeout=patience(5) * 1000)
        return patience(30) * 1000
