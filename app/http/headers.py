"""Security headers on every response, as a pure ASGI middleware (no per-request task or copy).

The pages load only their own ES modules and stylesheet, with no inline script, inline
style or `style=` attribute (frontend/templates), so the policy can allow 'self' alone.
"""

from starlette.types import ASGIApp, Message, Receive, Scope, Send

# Where the participant's browser may post a form: the completion redirects of the platforms.
RECRUITMENT_FORM_TARGETS = ("https://app.prolific.com", "https://www.mturk.com",
                            "https://workersandbox.mturk.com")
# MTurk shows an ExternalQuestion inside an iframe of its worker site
MTURK_FRAMERS = ("https://worker.mturk.com", "https://workersandbox.mturk.com",
                 "https://www.mturk.com")

APP_POLICY = {
    "default-src": "'none'",
    "script-src": "'self'",
    "style-src": "'self'",  # scripts set sizes through element.style, which CSP allows
    "img-src": "'self' data:",  # data: for the empty favicon
    "connect-src": "'self'",
    "form-action": " ".join(("'self'", *RECRUITMENT_FORM_TARGETS)),
    "frame-ancestors": "'none'",
    "base-uri": "'none'",
}
# Swagger UI and ReDoc (served outside production only) come from a CDN with an inline
# start-up script; their pages get this looser policy and nothing else does.
DOCS_POLICY = APP_POLICY | {
    "script-src": "'self' 'unsafe-inline' https://cdn.jsdelivr.net",
    "style-src": "'self' 'unsafe-inline' https://cdn.jsdelivr.net https://fonts.googleapis.com",
    "font-src": "https://fonts.gstatic.com",
    "img-src": "'self' data: https://fastapi.tiangolo.com https://cdn.redoc.ly",
    "worker-src": "blob:",
}
# answers that hold a participant's session or the researcher's data: no cache may keep them
NO_STORE_PREFIXES = ("/api/", "/researcher")
NO_STORE = [(b"cache-control", b"no-store")]
OTHER_HEADERS = {
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "DENY",
    "cross-origin-opener-policy": "same-origin",
}


def policy_header(policy: dict[str, str]) -> str:
    """A Content-Security-Policy value from {directive: sources}."""
    return "; ".join(f"{directive} {sources}" for directive, sources in policy.items())


def encoded_headers(policy: dict[str, str], framed_by: tuple[str, ...] = (),
                    form_targets: tuple[str, ...] = ()) -> list[tuple[bytes, bytes]]:
    """The raw ASGI headers for one policy plus the fixed ones; `framed_by` origins may
    show the pages in a frame (X-Frame-Options cannot name them, so it is left out), and
    forms may also post to `form_targets` (a study's configured MTurk submit hosts)."""
    extra_targets = [t for t in form_targets if t not in RECRUITMENT_FORM_TARGETS]
    if extra_targets:
        policy = policy | {"form-action": " ".join((policy["form-action"], *extra_targets))}
    headers = OTHER_HEADERS | {"content-security-policy": policy_header(policy)}
    if framed_by:
        framed = policy | {"frame-ancestors": " ".join(("'self'", *framed_by))}
        headers = {k: v for k, v in headers.items() if k != "x-frame-options"}
        headers["content-security-policy"] = policy_header(framed)
    return [(name.encode(), value.encode()) for name, value in headers.items()]


class SecurityHeaders:
    """Add CSP, nosniff, Referrer-Policy, frame and opener headers to every HTTP response,
    and `Cache-Control: no-store` to the API's and the researcher page's.

    A header the app already set is kept; `docs_paths` get DOCS_POLICY; `framed_by`
    origins (MTurk's, when an MTurk study is served) may frame the pages, and forms may
    post to `form_targets`.
    """

    def __init__(self, app: ASGIApp, docs_paths: tuple[str, ...] = (),
                 framed_by: tuple[str, ...] = (), form_targets: tuple[str, ...] = ()) -> None:
        self.app = app
        self.docs_paths = frozenset(docs_paths)
        self.app_headers = encoded_headers(APP_POLICY, framed_by, form_targets)
        self.docs_headers = encoded_headers(DOCS_POLICY)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        extra = self.docs_headers if scope["path"] in self.docs_paths else self.app_headers
        if scope["path"].startswith(NO_STORE_PREFIXES):
            extra = extra + NO_STORE

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                present = {name.lower() for name, _ in message.get("headers", [])}
                added = [(n, v) for n, v in extra if n not in present]
                message = {**message, "headers": [*message.get("headers", []), *added]}
            await send(message)

        await self.app(scope, receive, send_with_headers)
