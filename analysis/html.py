"""Self-contained HTML reports: jinja2 templates (autoescaped) with figures embedded as data URIs.

The reports (analysis/report.py, app/interaction/report.py) and the preregistration
(app/prereg/write.py) render through `render_page`; their templates are in analysis/templates/
and extend `base.html.j2`.
"""

import base64
import mimetypes
from pathlib import Path

import jinja2

TEMPLATES = Path(__file__).resolve().parent / "templates"


def figure_data_uri(figure: str | Path) -> str:
    """A PNG or SVG file as a `data:` URI."""
    path = Path(figure)
    mime = mimetypes.types_map.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode()}"


def render_page(template: str, filters: dict | None = None, **context) -> str:
    """Render one of analysis/templates/ with `context`; `data_uri` and `filters` as filters."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True,
                             lstrip_blocks=True, keep_trailing_newline=True)
    env.filters.update(data_uri=figure_data_uri, **(filters or {}))
    return env.get_template(template).render(**context)
