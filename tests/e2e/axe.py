"""axe-core (npm, pinned in tests/e2e/package.json) run inside a Playwright page.

`make test` installs it (`npm ci --prefix tests/e2e`); without it the caller is skipped with
that command, as a browser test is without chromium.
"""

from pathlib import Path

import pytest

AXE_JS = Path(__file__).parent / "node_modules" / "axe-core" / "axe.min.js"
# each violation: its rule, impact and the first few offending elements' selectors
RUN = """async () => (await axe.run(document)).violations.map(v => ({
    id: v.id, impact: v.impact, nodes: v.nodes.length,
    targets: v.nodes.slice(0, 3).map(n => n.target.join(" "))}))"""


def axe_violations(page) -> list[dict]:
    """Every axe-core violation on the page as loaded (rule id, impact, count, targets)."""
    if not AXE_JS.is_file():
        pytest.skip(f"{AXE_JS} is absent: npm ci --prefix tests/e2e")
    page.add_script_tag(content=AXE_JS.read_text())
    return page.evaluate(RUN)
