"""What the researcher side reads from the server, in one place: the tables it queries, how a
session's status and times are read, and the few server rules its numbers must share.

app/researcher imports from app.server only this module (and its two route modules the HTTP
dependencies and bodies they declare); tests/test_architecture.py holds it. A researcher module
needing something new from the server adds it here, so the server's rooms stay free to change.
"""

from app.server.flow.balance import exclusion_reasons, lock_study, trial_speeds
from app.server.flow.balance import release as release_counts
from app.server.flow.completion_codes import codes_table
from app.server.flow.context import StudyContext
from app.server.flow.endings import FINISHED
from app.server.flow.places import Cutoffs, status_cutoffs
from app.server.flow.plan import trial_steps
from app.server.flow.recruitment import normalise_external_id, preview_path
from app.server.flow.sessions import as_utc, session_status
from app.server.flow.state import progress_of, static_trial
from app.server.prolific import ProlificClient, ProlificRefused, ProlificUnreachable
from app.server.schemas import SERVER_EVENTS, WithdrawalByExternalId, WithdrawalCreate
from app.server.storage.tables import (
    Event,
    Participant,
    PaymentAudit,
    PredictionRow,
    Submission,
    TrialDraft,
    TrialResponse,
    WithdrawalAudit,
)

__all__ = [
    # the tables the exports, dashboard, replay, payments and withdrawal read or delete from
    "Event", "Participant", "PaymentAudit", "PredictionRow", "Submission", "TrialDraft",
    "TrialResponse", "WithdrawalAudit",
    # one study as the server loaded it, and how a session's status and times are read
    "StudyContext", "Cutoffs", "status_cutoffs", "session_status", "as_utc", "FINISHED",
    "progress_of", "trial_steps", "static_trial",
    # the server's own exclusion counts, so the exports and the live numbers agree with it
    "exclusion_reasons", "trial_speeds",
    # a withdrawal takes its session out of the balance counts under the study's lock
    "lock_study", "release_counts",
    # the study's codes and links, and how a platform's participant id is spelled
    "codes_table", "preview_path", "normalise_external_id",
    # the wire names a withdrawal and the events export share with the API
    "SERVER_EVENTS", "WithdrawalByExternalId", "WithdrawalCreate",
    # Prolific's API, which the payment sheet's approvals call
    "ProlificClient", "ProlificRefused", "ProlificUnreachable",
]
