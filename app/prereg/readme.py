"""A Markdown table of the README, read by its heading (the deviations from the paper are kept
there once, and the preregistration shows them as they are)."""

import re

from app.prereg.document import Table

_CELL_BORDER = re.compile(r"(?<!\\)\|")


def readme_table(text: str, heading: str) -> Table:
    """The first table after the line `heading`; ValueError naming the heading if none."""
    lines = text.splitlines()
    if heading not in lines:
        raise ValueError(f"README.md: no heading {heading!r}")
    after = lines[lines.index(heading) + 1:]
    start = next((i for i, line in enumerate(after) if line.startswith(("|", "## "))), None)
    if start is None or not after[start].startswith("|"):
        raise ValueError(f"README.md: no table under {heading!r}")
    block = []
    for line in after[start:]:
        if not line.startswith("|"):
            break
        block.append(cells(line))
    header, _separator, *rows = block
    return Table(tuple(header), tuple(tuple(row) for row in rows))


def cells(line: str) -> list[str]:
    """A table row's cells, stripped."""
    return [cell.strip() for cell in _CELL_BORDER.split(line.strip())[1:-1]]
