"""Write a study's preregistration: preregistration.md and a self-contained
preregistration.html (analysis/templates/prereg.html.j2), both from one Document."""

import re
from pathlib import Path

from markupsafe import Markup, escape

from analysis.html import render_page
from app.core.files import atomic_path
from app.prereg.document import Document, Items, Table, to_markdown
from app.prereg.inputs import gather
from app.prereg.sections import preregistration
from app.settings import Settings

_CODE = re.compile(r"`([^`]+)`")
_STRONG = re.compile(r"\*\*([^*]+)\*\*")


def write_prereg(settings: Settings, study_id: str, out_dir: Path) -> list[Path]:
    """Write preregistration.md and .html for `study_id` into `out_dir`; the paths written."""
    document = preregistration(gather(settings, study_id))
    out_dir = Path(out_dir)
    written = []
    for name, text in (("preregistration.md", to_markdown(document)),
                       ("preregistration.html", to_html(document))):
        with atomic_path(out_dir / name) as tmp:
            tmp.write_text(text)
        written.append(out_dir / name)
    return written


def to_html(document: Document) -> str:
    """The document as one HTML page with no external file (the reports' base template)."""
    return render_page("prereg.html.j2", filters={"inline": inline_html, "kind": block_kind},
                       doc=document, page_width_px=1100)


def block_kind(block) -> str:
    """table, items or text: which markup a block gets."""
    if isinstance(block, Table):
        return "table"
    return "items" if isinstance(block, Items) else "text"


def inline_html(text: str) -> Markup:
    """Text escaped, with Markdown's `code` and **bold** spans as HTML."""
    html = str(escape(text))
    html = _CODE.sub(r"<code>\1</code>", html)
    return Markup(_STRONG.sub(r"<strong>\1</strong>", html))
