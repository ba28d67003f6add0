"""The one error type of the study's write path: an HTTP status and a `field: message`.

A refusal a participant can meet also carries a `Notice`: the same refusal in plain
language with what to do on the recruiting platform. The page shows the notice; the
field name stays in the API answer and the logs.
"""

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Notice:
    """What a participant is told: a heading, the text, and `action`, a choice the page
    offers besides (e.g. `takeover`: continue in this tab)."""

    title: str
    text: str
    action: str = ""

    def as_dict(self) -> dict:
        """The notice as the error body's `notice`."""
        return asdict(self)


class Refused(Exception):
    """A request the study cannot accept: HTTP status, `field: message`, and optionally a
    notice for the participant's page and response headers (e.g. Retry-After)."""

    def __init__(self, status: int, detail: str, notice: Notice | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.notice = notice
        self.headers = headers or {}
