"""Refuse to serve a study whose trial bank changed under sessions that already ran it.

Each session stores the sha256 of the bank it ran (Participant.bank_sha256). The bank
pins the trials and both models' answers, so sessions of two banks cannot be pooled in
one analysis without the researcher deciding so (setting `allow_bank_change`).
"""

from sqlalchemy import func, select
from sqlalchemy.engine import Engine

from app.server.storage.tables import Participant

SHORT = 12  # hex characters of a bank hash in messages


class BankChanged(RuntimeError):
    """Sessions of this study ran another trial bank than the one loaded."""


def banks_run(engine: Engine, study_id: str) -> dict[str, int]:
    """Bank sha256 -> sessions that ran it (pilots and sessions older than the hash left out)."""
    query = (select(Participant.bank_sha256, func.count())
             .where(Participant.study_id == study_id, Participant.pilot.is_(False),
                    Participant.bank_sha256 != "")
             .group_by(Participant.bank_sha256))
    with engine.connect() as conn:
        return dict(conn.execute(query).all())


def check_bank_unchanged(engine: Engine, study_id: str, bank_sha256: str) -> None:
    """Raise BankChanged if any session (pilots aside) of the study ran another bank."""
    runs = banks_run(engine, study_id)
    if set(runs) <= {bank_sha256}:
        return
    ran = ", ".join(f"{n} ran bank {sha[:SHORT]}{' (the loaded one)' if sha == bank_sha256 else ''}"
                    for sha, n in sorted(runs.items(), key=lambda item: (-item[1], item[0])))
    raise BankChanged(
        f"{study_id}: the trial bank changed under a running study: of its sessions (pilots "
        f"not counted) {ran}, but the loaded bank is {bank_sha256[:SHORT]}; their trials and "
        "model answers differ. Restore the bank those sessions ran, or serve this one anyway "
        "with `tomstudy serve --allow-bank-change` (or TOMSTUDY_ALLOW_BANK_CHANGE=1)")
