"""The one error type of the study's write path: an HTTP status and a `field: message`."""


class Refused(Exception):
    """A request the study cannot accept: HTTP status, `field: message`, optional headers."""

    def __init__(self, status: int, detail: str, headers: dict[str, str] | None = None) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.headers = headers or {}
