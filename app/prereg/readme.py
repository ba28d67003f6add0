"""A Markdown table of a documentation page, read by its heading (the deviations from the paper
are kept once, in docs/reproduce/departures.md, and the preregistration shows them as they are)."""

import re

from app.prereg.document import Table

_CELL_BORDER = re.compile(r"(?<!\\)\|")


def readme_table(text: str, heading: str, source: str = "docs/reproduce/departures.md") -> Table:
    """The first table after the line `heading`; ValueError naming the file and heading if none."""
    lines = text.splitlines()
    if heading not in lines:
        raise ValueError(f"{source}: no heading {heading!r}")
    after = lines[lines.index(heading) + 1:]
    start = next((i for i, line in enumerate(after) if line.startswith(("|", "## "))), None)
    if start is None or not after[start].startswith("|"):
        raise ValueError(f"{source}: no table under {heading!r}")
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
