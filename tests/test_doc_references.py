"""Every place in the code, configs and docs that sends a reader to a section finds it: a
`README "X"` (or `README, "X"`, `README: X`) names a heading the README has, and a
`docs/....md` path names a page that exists (with `, "X"` after it, a heading that page has).
The README was cut to a map and its sections moved to docs/; an error message pointing a lab
at a section that is gone leaves them stuck. test_readme_links.py checks the README's own
links, `mkdocs build --strict` the site's."""

import os
import re
from pathlib import Path

from tests.conftest import REPO

SUFFIXES = {".py", ".sh", ".yaml", ".yml", ".md", ".js", ".html", ".j2", ".toml"}
NAMES = {"Dockerfile", "Makefile"}
SKIPPED_DIRS = {".git", ".venv", "var", "site", "node_modules", "__pycache__", "build", "dist",
                ".pytest_cache", ".ruff_cache", ".hypothesis"}
QUOTED = r'\\?"(?P<{0}>[^"\\]+)\\?"'
README_REF = re.compile(r"README(?:\.md)?(?:\s*[,:]\s*|\s+)" + QUOTED.format("quoted")
                        + r"|README(?:\.md)?\s*[,:]\s*(?P<bare>[A-Z][^)\";\n]*[^)\";\s])")
DOCS_REF = re.compile(r"(?P<page>docs/[\w/.-]+?\.md)(?:\s*[,:]\s*" + QUOTED.format("heading")
                      + ")?")
# the next line continues a comment or a string: joined so a reference may wrap
CONTINUATION = re.compile(r'^\s*(?:#|//|\*|")?\s*')
# Frozen files (the paper study's config and its bundle must keep their bytes, so the bundle
# keeps verifying): their comments still name the README's old sections. The text is now in
# docs/reproduce/instrument.md, "The design goal: would the primary test confirm the hypothesis?"
PAPER, BUNDLED = "study_configs/paper_study.yaml", "study_configs/bundles/paper_study/configs/"
FROZEN_STALE = {(PAPER, 90, "README", "The design goal"), (PAPER, 107, "README", "The design goal"),
                (BUNDLED + "paper_study.yaml", 63, "README", "The design goal"),
                (BUNDLED + "paper_study.yaml", 80, "README", "The design goal")}


def source_files():
    """The kinds of text file that can name a section (this one's examples aside), outside data
    and build dirs."""
    for root, dirs, files in os.walk(REPO):
        dirs[:] = sorted(d for d in dirs if d not in SKIPPED_DIRS and not d.endswith(".egg-info"))
        for name in sorted(files):
            path = Path(root) / name
            if (path.suffix in SUFFIXES or name in NAMES) and path != Path(__file__):
                yield path


def headings(page: Path) -> list[str]:
    """The Markdown headings of a page, fenced code blocks (whose `#` are comments) left out."""
    found, fenced = [], False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := re.match(r"#{1,6}\s+(.+?)\s*#*$", line)):
            found.append(m.group(1))
    return found


def names_a_heading(page: Path, section: str) -> bool:
    """True when the page has the heading, or one that begins with it ("Endings: one code...")."""
    return any(h == section or (h.startswith(section) and not h[len(section)].isalnum())
               for h in headings(page))


def joined(lines: list[str], i: int) -> str:
    """Line i with the next one appended, so a reference wrapped over two lines is read whole."""
    line, following = lines[i], lines[i + 1] if i + 1 < len(lines) else ""
    if following.lstrip().startswith('"'):  # Python's implicit string concatenation
        line = re.sub(r'"\s*$', "", line)
    return line.rstrip() + " " + CONTINUATION.sub("", following, count=1)


def references(path: Path):
    """(line number, target, section or None) for each README or docs/ reference in a file."""
    lines = path.read_text(errors="replace").splitlines()
    for i, line in enumerate(lines):
        text = joined(lines, i)
        for m in README_REF.finditer(text):
            if m.start() < len(line):
                yield i + 1, "README", (m.group("quoted") or m.group("bare")).strip()
        for m in DOCS_REF.finditer(text):
            if m.start() < len(line):
                yield i + 1, m.group("page"), m.group("heading")


def broken_references() -> list[tuple[str, int, str, str | None]]:
    """Every reference whose page or heading does not exist, as (file, line, target, section)."""
    broken = []
    for path in source_files():
        rel = path.relative_to(REPO).as_posix()
        for line, target, section in references(path):
            page = REPO / ("README.md" if target == "README" else target)
            if not page.is_file() or (section and not names_a_heading(page, section)):
                broken.append((rel, line, target, section))
    return broken


def test_every_section_a_file_names_exists():
    broken = [b for b in broken_references() if b not in FROZEN_STALE]
    assert broken == [], f"{len(broken)} references to a page or heading that does not exist:\n" \
        + "\n".join(f"{f}:{n}: {t}" + (f' "{s}"' if s else "") for f, n, t, s in broken)


def test_the_frozen_exceptions_are_still_there():
    # when the paper study is ever re-frozen with current references, drop them from the list
    assert set(broken_references()) >= FROZEN_STALE


def test_the_scanner_reads_each_form_of_reference(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text('# (README, "Endings") and README "The\n# design goal" and\n'
                      'x = ("(README: Upgrading tomstudy on a running study)", "README \\"Pre: "\n'
                      '     "adding\\")")  # docs/run/go-live.md, "Going live"; docs/x.md\n')
    assert list(references(sample)) == [
        (1, "README", "Endings"), (1, "README", "The design goal"),
        (3, "README", "Upgrading tomstudy on a running study"), (3, "README", "Pre: adding"),
        (4, "docs/run/go-live.md", "Going live"), (4, "docs/x.md", None)]
    assert names_a_heading(REPO / "docs/run/go-live.md", "Endings")
    assert not names_a_heading(REPO / "docs/run/go-live.md", "End")
