"""The limits' defaults are written once in app/http/API.md, and they are app/settings.py's;
the hosting page's bullet (docs/run/hosting.md) quotes the same values."""

import re

from app.settings import Settings
from tests.conftest import REPO

API = (REPO / "app" / "http" / "API.md").read_text()
LIMITS = ("rate_limit_starts", "rate_limit_requests", "researcher_lockout")


def section(text: str, title: str) -> str:
    """The text of the markdown section `title`, up to the next heading."""
    return re.search(rf"^## {title}\n(.*?)(?=^## )", text, re.S | re.M).group(1)


def test_the_api_page_states_each_limit_once_with_the_settings_default():
    table = dict(re.findall(r"^\| `TOMSTUDY_(\w+)` \|.*\| `([^`]+)` \|$",
                            section(API, "Limits on anonymous traffic"), re.M))
    assert table == {name.upper(): Settings.model_fields[name].default for name in LIMITS}
    assert Settings.model_fields["rate_limit_storage"].default == "memory://"
    current = API.split("### Changes")[0]  # the changelog keeps the history
    for name in LIMITS:
        assert current.count(f"`TOMSTUDY_{name.upper()}`") == 1, name


def test_the_hosting_page_quotes_the_same_defaults():
    page = (REPO / "docs" / "run" / "hosting.md").read_text()
    bullet = page[page.index("**Anonymous traffic is bounded"):][:1200]
    for name in ("rate_limit_starts", "rate_limit_requests"):
        quoted = re.search(rf"`TOMSTUDY_{name.upper()}`[^`]*?\(default\s+`([^`]+)`", bullet, re.S)
        assert quoted and quoted.group(1) == Settings.model_fields[name].default, name
