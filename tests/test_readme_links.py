"""The README is a map into docs/: every relative link in it names a file that exists (the
site's own links are checked by `mkdocs build --strict`, which `make test` runs)."""

import re

from tests.conftest import REPO

LINK = re.compile(r"\]\(([^)#\s]+)(#[^)]*)?\)")


def test_every_relative_link_in_the_readme_names_a_file():
    targets = [t for t, _ in LINK.findall((REPO / "README.md").read_text())
               if "://" not in t]
    assert len(targets) > 10
    assert [t for t in targets if not (REPO / t).is_file()] == []


def test_the_readme_stays_a_map():
    assert len((REPO / "README.md").read_text().splitlines()) <= 200
