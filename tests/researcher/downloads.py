"""What the researcher tests download: one export's CSV text over the app, and the formula a
participant typed, which every export must keep as text."""

from tests.server.flow import ADMIN

FORMULA = '=HYPERLINK("http://x","y")'


def export(client, study_id: str, what: str) -> str:
    """GET one export's CSV text."""
    r = client.get(f"/api/researcher/export/{what}.csv?study_id={study_id}", headers=ADMIN)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/csv")
    return r.text
