"""The preregistration as one data structure (sections of paragraphs, lists and tables), and its
Markdown; the HTML page renders the same structure (app/prereg/write.py)."""

from dataclasses import dataclass


@dataclass(frozen=True)
class Table:
    """A table: a header row and rows of text cells."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Items:
    """A bulleted list."""

    items: tuple[str, ...]


Block = str | Table | Items  # a paragraph, a table or a list


@dataclass(frozen=True)
class Section:
    """One heading of the document and what follows it."""

    title: str
    blocks: tuple[Block, ...]

    @property
    def anchor(self) -> str:
        """The section's id in the HTML page."""
        return "-".join(self.title.lower().replace(",", "").split())


@dataclass(frozen=True)
class Document:
    """A whole preregistration: its title and its sections, in order."""

    title: str
    sections: tuple[Section, ...]


def to_markdown(document: Document) -> str:
    """The document as Markdown (GitHub tables)."""
    parts = [f"# {document.title}"]
    for section in document.sections:
        parts.append(f"## {section.title}")
        parts += [block_markdown(block) for block in section.blocks]
    return "\n\n".join(parts) + "\n"


def block_markdown(block: Block) -> str:
    """One paragraph, list or table as Markdown."""
    if isinstance(block, Table):
        lines = [row_markdown(block.header), "|" + "---|" * len(block.header)]
        return "\n".join(lines + [row_markdown(row) for row in block.rows])
    if isinstance(block, Items):
        return "\n".join(f"- {item}" for item in block.items)
    return block


def row_markdown(cells: tuple[str, ...]) -> str:
    """A table row, its pipes escaped and line breaks folded."""
    return "| " + " | ".join(" ".join(c.replace("|", "\\|").split()) for c in cells) + " |"
