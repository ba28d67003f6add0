"""In chromium: a consent takes a place, so a page whose consent meets a study running its cap
says why nothing happens yet, and goes on by itself once there is room (issue 32 item 2)."""

import shutil

import httpx
import pytest
import yaml
from playwright.sync_api import expect

from app.layout import Layout
from tests.conftest import SmallStudy, free_port, freeze_bundle_of, patience, start_server
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import VIEWPORT, fresh_recruitment, visible
from tests.server.flow import Participant, new_id, prolific

pytestmark = [pytest.mark.browser]
CAPPED = "capped_study"


@pytest.fixture(scope="module")
def capped_server(browser_study, tmp_path_factory):
    """The browser study with a live cap of one session; yields (url, the session's token)."""
    root = tmp_path_factory.mktemp("capped")
    shutil.copytree(browser_study.configs_dir, root / "configs")
    shutil.copytree(browser_study.data_dir, root / "var")
    layout = Layout(root / "var")
    shutil.copytree(layout.bank_dir(BROWSER_STUDY), layout.bank_dir(CAPPED))
    config = yaml.safe_load((root / "configs" / f"{BROWSER_STUDY}.yaml").read_text())
    config |= {"target_sample_size": 1, "max_live_sessions_per_target": 1}
    (root / "configs" / f"{CAPPED}.yaml").write_text(yaml.safe_dump(config))
    study = SmallStudy(root / "var", root / "configs", CAPPED)
    freeze_bundle_of(study)
    port = free_port()
    proc = start_server(study, f"sqlite:///{root / 'study.db'}", port, log=root / "server.log")
    yield f"http://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(timeout=patience(10))


def test_a_consent_waiting_for_room_says_so_then_goes_on(chromium, capped_server):
    page = chromium.new_context(viewport=VIEWPORT).new_page()
    page.goto(f"{capped_server}/s/{CAPPED}?{fresh_recruitment()}")
    visible(page, "consent")  # a start takes no place
    with httpx.Client(base_url=capped_server, timeout=patience(30)) as http:
        first = Participant(http, CAPPED)
        first.start(**prolific("first-" + new_id()))
        assert first.consent().status_code == 200  # the study's one place, taken meanwhile
        page.check("#consent-check")
        page.click("#consent-agree")
        expect(page.locator("#consent-status")).to_contain_text(
            "Many people are taking this study")
        assert page.is_visible("#screen-consent")
        ended = first.post("screen-out", {"submission_id": new_id(),
                                          "reason": "window_too_small"})
        assert ended.status_code == 200  # the place is free again
    visible(page, "instructions")  # the page's retry got in
    page.context.close()
