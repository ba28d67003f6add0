"""A client of Prolific's researcher API: the three calls the study needs.

- `GET  submissions/{id}/`: is the link's SESSION_ID a submission of this STUDY_ID by this
  PROLIFIC_PID (`check_submission`);
- `POST submissions/{id}/transition/` with `{"action": "APPROVE"}` (`approve`);
- `POST submissions/{id}/request-return/` with `{"request_return_reasons": [...]}`
  (`request_return`).

Every request carries `Authorization: Token <token>` (docs.prolific.com, API reference,
Submissions). Written against Prolific's documented API and tested against a local stand-in
(tests/server/prolific_standin.py) that implements these endpoints, never against the live Prolific.
A network failure, a timeout, a 5xx, a 429 or a refused token raise `ProlificUnreachable`: the
caller decides what an unanswered question means (sessions: admit and re-check, see
prolific_check.py).
"""

from dataclasses import dataclass

import httpx

from app.settings import Settings

CONFIRMED = "confirmed"  # Prolific lists the submission, of this study, by this participant
UNKNOWN = "unknown"  # Prolific does not know it, or it is another study's or person's
PENDING = "pending"  # Prolific could not be asked yet; re-checked until it answers


class ProlificUnreachable(Exception):
    """Prolific did not answer the question (network, timeout, 5xx, 429, token refused)."""


class ProlificRefused(Exception):
    """Prolific answered and refused the action (e.g. approving a submission not awaiting
    review); the message carries its status code and detail."""


@dataclass(frozen=True)
class ProlificClient:
    """Prolific's researcher API at `base_url`, authenticated with `token`."""

    base_url: str
    token: str
    timeout_s: float = 5.0

    def _client(self) -> httpx.AsyncClient:
        return httpx.AsyncClient(base_url=self.base_url.rstrip("/") + "/",
                                 headers={"Authorization": f"Token {self.token}"},
                                 timeout=self.timeout_s)

    async def _send(self, method: str, path: str, body: dict | None = None) -> httpx.Response:
        try:
            async with self._client() as client:
                answer = await client.request(method, path, json=body)
        except httpx.HTTPError as err:
            raise ProlificUnreachable(f"{method} {path}: {type(err).__name__}: {err}") from err
        if answer.status_code in (401, 403, 429) or answer.status_code >= 500:
            raise ProlificUnreachable(f"{method} {path}: HTTP {answer.status_code} "
                                      f"{_detail(answer)}")
        return answer

    async def get_submission(self, submission_id: str) -> dict | None:
        """The submission `submission_id` as Prolific describes it, or None if it has none."""
        answer = await self._send("GET", f"submissions/{submission_id}/")
        if answer.status_code in (400, 404):
            return None
        _require_ok(answer, "GET submission")
        return answer.json()

    async def check_submission(self, submission_id: str, study_id: str,
                               participant_id: str) -> str:
        """CONFIRMED if `submission_id` is a submission of `study_id` by `participant_id`,
        else UNKNOWN (ProlificUnreachable when Prolific cannot say)."""
        found = await self.get_submission(submission_id)
        if found is None:
            return UNKNOWN
        # the single-submission answer names the person `participant`, the lists
        # `participant_id`: accept either spelling
        person = found.get("participant") or found.get("participant_id") or ""
        same = (str(found.get("study_id", "")).lower() == study_id.lower()
                and str(person).lower() == participant_id.lower())
        return CONFIRMED if same else UNKNOWN

    async def approve(self, submission_id: str) -> dict:
        """Approve (and so pay) a submission awaiting review; Prolific's answer."""
        answer = await self._send("POST", f"submissions/{submission_id}/transition/",
                                  {"action": "APPROVE"})
        _require_ok(answer, "APPROVE")
        return answer.json()

    async def request_return(self, submission_id: str, reasons: list[str]) -> dict:
        """Ask the participant to return the submission, giving `reasons`; Prolific's answer."""
        answer = await self._send("POST", f"submissions/{submission_id}/request-return/",
                                  {"request_return_reasons": reasons})
        _require_ok(answer, "request-return")
        return answer.json()


def client_from(settings: Settings) -> "ProlificClient | None":
    """The client of the configured Prolific API, or None without a token (nothing is asked)."""
    if not settings.prolific_token:
        return None
    return ProlificClient(settings.prolific_api_url, settings.prolific_token,
                          settings.prolific_timeout_s)


def _require_ok(answer: httpx.Response, what: str) -> None:
    if not answer.is_success:
        raise ProlificRefused(f"{what}: Prolific answered HTTP {answer.status_code} "
                              f"{_detail(answer)}")


def _detail(answer: httpx.Response) -> str:
    """Prolific's error text, shortened to one line."""
    return " ".join(answer.text.split())[:200]
