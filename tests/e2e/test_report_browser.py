"""report.html in Debian's chromium: the answer fills the first screen, axe-core finds nothing."""

import gzip
import json

import pytest

from analysis.report import render_html, run_analyze
from analysis.verdicts import primary_sentence
from app.core.contracts import StudyInputs
from tests.analysis.report_inputs import BANK_JSON, MODELS, RULES, simulated_export
from tests.conftest import REPO
from tests.e2e.axe import axe_violations

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SCREEN = {"width": 1280, "height": 900}
SCREENSHOTS = REPO / "var" / "screenshots"
# the first screen must hold each world's verdict line
ABOVE_THE_FOLD = """() => [...document.querySelectorAll('#answer ul.verdicts li')].map(li => ({
    world: li.dataset.world, text: li.textContent.trim(),
    bottom: li.getBoundingClientRect().bottom}))"""


@pytest.fixture(scope="module")
def reports(tmp_path_factory) -> dict:
    """A coarse pilot's report.html as `analyze` writes it, and the same summary with the
    equivalence test's keys and the direct test rendered beside it."""
    root = tmp_path_factory.mktemp("report")
    bank = root / "bank.json.gz"
    bank.write_bytes(gzip.compress(BANK_JSON))
    inputs = StudyInputs(config={"exclusions": RULES.model_dump()}, rules=RULES, bank=bank,
                         models=MODELS)
    simulated_export("coarse", 12, seed=3).to_csv(root / "export.csv", index=False)
    out = root / "report"
    run_analyze("paper_study", out, root / "export.csv", "", inputs)
    summary = json.loads((out / "summary.json").read_text())
    summary["primary"]["highway"] |= {"ci95_low": -0.5, "ci95_high": -0.2, "sesoi": 0.05,
                                      "tost_p": 0.9, "bf10": 12.0, "conclusion": "ours"}
    summary["direct"] = {"highway": {"verdict": "coarse", "exploratory": False, "variants": {
        "coarse_scene": {"mean_diff": -0.03, "ci95_low": -0.05, "ci95_high": -0.01,
                         "p_holm": 0.004, "verdict": "coarse"}}}}
    (out / "report_with_equivalence.html").write_text(
        render_html(summary, sorted(out.glob("*.png"))))
    return {"analyze": (out / "report.html", json.loads((out / "summary.json").read_text())),
            "equivalence": (out / "report_with_equivalence.html", summary)}


@pytest.mark.parametrize("shape", ["analyze", "equivalence"])
def test_report_answers_on_its_first_screen_with_no_axe_violation(reports, chromium, shape):
    path, summary = reports[shape]
    page = chromium.new_page(viewport=SCREEN)
    page.goto(path.as_uri())
    lines = page.evaluate(ABOVE_THE_FOLD)
    assert [line["world"] for line in lines] == ["highway", "obstacle"]
    for line in lines:
        assert line["text"] == primary_sentence(line["world"], summary["primary"][line["world"]])
        assert line["bottom"] < SCREEN["height"]
    first_table = page.locator("table").first
    assert first_table.evaluate("t => t.closest('#details') !== null")
    assert page.locator("main").count() == 1
    assert axe_violations(page) == []
    if shape == "analyze":
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOTS / "report_first_page.png"))
    page.close()
