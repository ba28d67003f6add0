"""The dashboard of a study with the CTRV plug-in, in Debian's chromium: every predictor in the
error plots and table, and the replay draws the plug-in's moves with its own colour."""

import asyncio

import pytest

from app.core.contracts import model_color
from app.pilot.bots import run_bots
from tests.conftest import free_port, patience, start_server
from tests.e2e.pages import CANVAS_COLOUR_COUNT, researcher_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]

LABELS = ["Ours", "VAE", "Const. vel.", "Coarse observer", "Coarse, scene", "Coarse, momentum",
          "ctrv", "Policy"]
# Pixels of a canvas within `tolerance` levels per channel of an RGB colour. The replay strokes
# a model's moves at 0.9 alpha and anti-aliased, so few of its pixels are the colour exactly;
# 10 levels take in its squares over its own line and its line over dark ground, and nothing
# else the replay draws (0 pixels with the plug-in's moves left out).
COLOUR_PIXELS = """(c, [rgb, tolerance]) => {
    const data = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < data.length; i += 4) {
        if (rgb.every((v, k) => Math.abs(data[i + k] - v) <= tolerance)) n += 1;
    }
    return n;
}"""
COLOUR_TOLERANCE = 10


def rgb(hex_colour: str) -> list[int]:
    """[r, g, b] of a "#RRGGBB" colour."""
    return [int(hex_colour[k:k + 2], 16) for k in (1, 3, 5)]


@pytest.fixture(scope="module")
def plugin_server(ctrv_study, tmp_path_factory):
    """`tomstudy serve` of the CTRV study, after two coarse bots took it through HTTP."""
    root = tmp_path_factory.mktemp("plugin-server")
    port = free_port()
    proc = start_server(ctrv_study, f"sqlite:///{root / 'study.db'}", port,
                        log=root / "server.log", TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    url = f"http://127.0.0.1:{port}"
    results = asyncio.run(run_bots(url, ctrv_study.study_id, "coarse", 2, concurrency=2, seed=5))
    assert [r.error for r in results if r.error] == []
    yield url
    proc.terminate()
    proc.wait(timeout=patience(10))


def test_the_dashboard_shows_every_predictor_and_replays_the_plugin(plugin_server, chromium):
    page, errors = researcher_page(chromium, plugin_server)
    page.wait_for_selector("table.ci-table")
    heads = page.locator("table.ci-table th").all_inner_texts()
    assert heads == ["world", "n", *LABELS]
    plot = page.locator("svg.error-plot").first
    ticks = plot.locator("text.tick").evaluate_all("ts => ts.map(t => t.textContent)")
    assert [t for t in ticks if t in LABELS] == LABELS
    dots = plot.locator("circle.dot").evaluate_all("ds => ds.map(d => d.getAttribute('fill'))")
    assert model_color("ctrv") in dots
    page.locator("table.sessions tbody tr").first.locator("button").click()
    page.wait_for_selector(".trial-row")
    page.locator(".trial-row").nth(1).locator("button").click()
    page.wait_for_selector("#replay-view:not([hidden])")
    assert "ctrv" in page.locator("#replay-legend").inner_text()
    assert "error ctrv" in page.locator("#replay-click-table th").all_inner_texts()
    canvas = page.locator("#replay-canvas")
    assert canvas.evaluate(CANVAS_COLOUR_COUNT) > 10
    # the colour the page was given for the plug-in (its error-plot dots above), on the replay
    assert canvas.evaluate(COLOUR_PIXELS, [rgb(model_color("ctrv")), COLOUR_TOLERANCE]) > 0
    assert errors == []
    page.close()
