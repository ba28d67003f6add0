"""Session starts and researcher requests from one chosen loopback address (127.1.x.y), each
over a connection of its own, so the kernel may hand each one to any worker of a server."""

import uuid

import httpx

from tests.conftest import patience
from tests.server.flow import prolific


def start_once(port: int, study_id: str, source: str, name: str) -> int:
    """One session start from `source` to the server on `port`; its status."""
    transport = httpx.HTTPTransport(local_address=source)
    with httpx.Client(transport=transport, timeout=patience(20)) as client:
        return client.post(f"http://127.0.0.1:{port}/api/sessions", json={
            "study_id": study_id, "recruitment": prolific(name)}).status_code


def send_starts(ports: list[int], study_id: str, source: str, count: int) -> list[int]:
    """`count` starts of new participants from `source`, to `ports` in turn, one after
    another; their statuses.

    One at a time, each new connection wakes every worker waiting on the shared socket and
    any one may take it; a burst of connections would mostly go to one worker (asyncio
    accepts every pending connection on one wake-up)."""
    return [start_once(ports[i % len(ports)], study_id, source, uuid.uuid4().hex)
            for i in range(count)]


def researcher_status(port: int, study_id: str, source: str, token: str) -> int:
    """GET the researcher summary of `study_id` from `source` with bearer `token`; its
    status (not researcher_get: the request must leave from `source`, which needs a client)."""
    transport = httpx.HTTPTransport(local_address=source)
    with httpx.Client(transport=transport, timeout=patience(20)) as client:
        return client.get(f"http://127.0.0.1:{port}/api/researcher/summary",
                          params={"study_id": study_id},
                          headers={"Authorization": f"Bearer {token}"}).status_code
