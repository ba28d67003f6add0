"""The exports' codebook: every column's meaning, unit and allowed values, in one place.

`data_package` describes one export CSV as a Frictionless Data Package
(https://specs.frictionlessdata.io/): each column's type (from the contracts in
app/core/contracts.py), description, unit and constraints (the closed sets below as enums,
hashes as patterns), the export version and the study's hashes as the rows carry them, and
the CSV's path, sha256, size and row count. `frictionless validate FILE.datapackage.json`
then checks the CSV against it. A contract column without an entry here is an error
(tests/analysis/test_codebook.py), so the codebook cannot fall behind the exports.

It imports nothing from `app` but app/core/ (contracts, hashes), and not pandas.
"""

import re
from dataclasses import dataclass
from datetime import UTC, datetime

from app.core.contracts import (
    COARSE_OBSERVERS,
    EXPORT_VERSION,
    PILOT,
    PROLIFIC_UNCONFIRMED,
    SCHEMAS,
    STUDY_VERSION,
    WHAT,
    column_kinds,
)
from app.core.files import sha256_bytes

# The closed sets of values (tests/analysis/test_codebook.py checks each against the code
# that writes it, so a new value cannot miss the codebook)
RECRUITMENTS = ("prolific", "mturk", "open", PILOT)
OUTCOMES = ("completed", "failed_checks", "excluded", "declined_consent", "screened_out")
PROLIFIC_CHECKS = ("confirmed", *PROLIFIC_UNCONFIRMED)
ARMS = ("random", "models_disagree", "discriminability")
# `own` is the robot's segment end; the others are each world's two data-covered kinds, and
# `offset` is a bank's from before issue 22
START_KINDS = ("own", "same_lane", "adjacent_lane", "near", "mid", "far", "offset")
CLICK_INPUTS = ("mouse", "keyboard", "touch")
QUESTION_KINDS = ("likert", "text", "choice")
EVENT_SOURCES = ("telemetry", "server", "trial_history")
EVENT_KINDS = ("visibility_hidden", "visibility_shown", "resize", "clip_finished", "replay",
               "page_opened", "tab_takeover", "undo", "reset")
SESSION_STATUSES = ("ended", "in_progress", "awaiting_consent", "stale", "replaced")
ATTENTION_VERDICTS = ("passed", "failed", "none")
EXCLUSION_REASONS = ("failed_attention_check", "too_fast", "incomplete", PILOT, "replaced",
                     "prolific_unknown")

SHA256 = r"[0-9a-f]{64}"
# Frictionless field types of the contracts' kinds
FIELD_TYPES = {"text": "string", "int": "integer", "float": "number", "bool": "boolean",
               "time": "datetime"}
KIND_NOTES = {"text": "text, empty when absent", "int": "integer, -1 when not applicable",
              "float": "number, empty when absent", "bool": "True or False",
              "time": "ISO 8601 time in UTC, empty when absent"}


@dataclass(frozen=True)
class Column:
    """One column's entry: what it means, its unit, and its allowed values or pattern."""

    text: str
    unit: str = ""
    values: tuple = ()
    pattern: str = ""
    required: bool = False


@dataclass(frozen=True)
class StudyTerms:
    """The values a study's own config closes: its worlds and its survey questions' keys."""

    worlds: tuple[str, ...] = ()
    questions: tuple[str, ...] = ()


def one_of(values, separator: str) -> str:
    """A pattern of one or more of `values` joined by `separator`."""
    word = "(" + "|".join(re.escape(v) for v in values) + ")"
    return f"{word}({re.escape(separator)}{word})*"


# ---------------------------------------------------------------- every export's columns

SESSION = {
    "export_version": Column(
        f"The export's version (EXPORT_VERSION in app/core/contracts.py): {EXPORT_VERSION} "
        "since the participant's columns were renamed (app/http/API.md, Changes); an "
        "export without the column is version 1.", values=(EXPORT_VERSION,), required=True),
    "study_id": Column("The study's id (its config study_configs/<study_id>.yaml).",
                       required=True),
    "participant_id": Column(
        "The session's random public id (what the browser was given), never the platform's "
        "id: only the participants export links the two.", required=True),
    "config_sha256": Column(
        "SHA-256 of the study config the session ran (the validated config as canonical "
        "JSON; app/study/config.py config_sha256), so a study changed mid-way shows it row by "
        "row.", pattern=SHA256),
    "bank_sha256": Column(
        "SHA-256 of the trial bank the session ran (its JSON); the bank pins each model's "
        "hash beside its answers.", pattern=SHA256),
}
# every export but predictions (whose rows carry ours_sha256 and vae_sha256)
MODELS_SHA256 = {"models_sha256": Column(
    'JSON {"<world>": {"ours": sha256, "vae": sha256}} of the models the session\'s answers '
    "came from ({} before its first answered trial).")}
RECRUITMENT = Column(
    "How the session came: prolific, mturk, open (a lab's anonymous link) or pilot (a "
    "researcher's preview session: never counted, always excluded from the analysis).",
    values=RECRUITMENTS)
OUTCOME = Column(
    "The session's ending: completed, failed_checks (at least endings.min_failed attention "
    "checks failed), excluded (the study's exclusions removed it), declined_consent or "
    "screened_out (the device check failed); empty while it runs.", values=OUTCOMES)
REPLACED = Column("The attempt was replaced by a newer one of the same participant; the "
                  "analysis leaves it out (false in exports made before the column).")
PROLIFIC_CHECK = Column(
    "Prolific's word on the session's link (app/server/flow/prolific_check.py): confirmed, pending "
    "(Prolific not reachable yet) or unknown; empty when not asked (no Prolific API token, "
    "another platform, a pilot) and in exports made before the column. The analysis "
    "excludes pending and unknown sessions (prolific_unknown).", values=PROLIFIC_CHECKS)
BANK_TRIAL_ID = "The bank's trial id (the browser was given an opaque id, mapped back here)"


def _moves(who: str) -> dict[str, Column]:
    """A predictor's two action columns."""
    return {f"{who}_v{axis}": Column(f"{WHO[who]}: the predicted robot move's {axis} "
                                     "component from this start state.", unit="m/s")
            for axis in "xy"}


WHO = {"participant": "The participant's answer (clicked position difference / dt)",
       "ours": "Ours (the FSQ model family's answer, as the bank stores it)",
       "vae": "The VAE (the baseline model family's answer, as the bank stores it)",
       "cv": "Constant velocity (the robot's last segment velocity)",
       "policy": "The world's own policy rolled out from this start state (ground truth)"}

PREDICTIONS = {
    **SESSION,
    "recruitment": RECRUITMENT,
    "completed": Column("The session reached its done phase (survey stored)."),
    "outcome": OUTCOME,
    "replaced": REPLACED,
    "prolific_check": PROLIFIC_CHECK,
    "attention_passed": Column("The participant has failed no attention check so far."),
    "world": Column("The world the trial shows (one of the study's worlds)."),
    "world_position": Column("The world's place in the participant's session, 0 for the "
                             "first world."),
    "trial_id": Column(BANK_TRIAL_ID + "."),
    "trial_index": Column("The trial's position within its world (attention checks "
                          "included); practice trials count 0.. on their own, flagged by "
                          "is_practice."),
    "is_practice": Column("A practice trial (answered, not scored)."),
    "attention_check": Column("An attention check (the robot's true first move is the "
                              "answer; app/server/flow/validation.py)."),
    "arm": Column("How a main trial was chosen: random, or the selection rule's arm "
                  "(models_disagree, discriminability; docs/reproduce/trial-bank.md, \"Main "
                  "trials\"); empty for practice trials and attention checks, and in rows "
                  "stored before arms existed.", values=ARMS),
    "clip_sha256": Column("SHA-256 of the clip as shown (scene, time step and the trial's "
                          "browser payload), so a replay checks it shows the same clip.",
                          pattern=SHA256),
    "start_index": Column("Which of the trial's start states (0: the robot's own segment "
                          "end)."),
    "start_kind": Column("Where the robot's start came from: own (the robot's segment end), "
                         "or how a data-covered start relates to it (Highway same_lane, "
                         "adjacent_lane; Obstacle near, mid; recorded worlds near, far; "
                         "offset in banks built before issue 22).", values=START_KINDS),
    "step": Column("The predicted step from the start state, 0-based (steps_to_predict "
                   "per start state)."),
    "start_x": Column("The robot's start position, x (scene metres).", unit="m"),
    "start_y": Column("The robot's start position, y (scene metres).", unit="m"),
    "human_x": Column("The person agent's position, x: the human-driven agent in the scene "
                      "(fixed during the prediction), not the participant.", unit="m"),
    "human_y": Column("The person agent's position, y (see human_x).", unit="m"),
    "participant_click_x": Column("The participant's clicked robot position, x.", unit="m"),
    "participant_click_y": Column("The participant's clicked robot position, y.", unit="m"),
    **_moves("participant"), **_moves("ours"), **_moves("vae"), **_moves("cv"),
    **_moves("policy"),
    "ours_code": Column("Ours' discrete code: the FSQ code index of its latent."),
    "vae_code": Column("The VAE's discrete code: the k-means cluster of its latent."),
    "ours_sha256": Column("SHA-256 of the Ours checkpoint that gave ours_vx, ours_vy.",
                          pattern=SHA256),
    "vae_sha256": Column("SHA-256 of the VAE checkpoint that gave vae_vx, vae_vy.",
                         pattern=SHA256),
    "click_time_ms": Column("When the click was placed, since the trial was shown.",
                            unit="ms"),
    "click_input": Column("The device the click was placed with: mouse, keyboard (the arrow "
                          "keys and Enter) or touch (a pen too); empty when unknown (rows "
                          "stored before the column, clicks sent without it, the pilot bots' "
                          "and the simulated study's).", values=CLICK_INPUTS),
    "trial_duration_ms": Column("The trial's duration: the smaller of the client's and the "
                                "server's timing (the too-fast exclusion rule reads it).",
                                unit="ms"),
    "replays": Column("How often the participant replayed the trial's clips."),
    "submission_id": Column("The browser's UUID of the trial's submission (a retry with the "
                            "same id is stored once)."),
    "submitted_at": Column("When the server received the trial (ISO 8601, UTC; text in this "
                           "export)."),
}

SURVEY = {
    **SESSION, **MODELS_SHA256,
    "question": Column("The question's key (the study config's `survey`, in its order); an "
                       "optional question left blank has no row."),
    "kind": Column("The question's kind: likert, text (free text) or choice.",
                   values=QUESTION_KINDS),
    "answer": Column("The answer as text: a likert answer as its digits, a choice its option, "
                     "a text question the participant's own words. FREE TEXT MAY HOLD "
                     "PERSONAL DATA (names, places, contact details): read it before "
                     "sharing the export."),
    "answered_at": Column("When the server received the survey."),
}

EVENTS = {
    **SESSION, **MODELS_SHA256,
    "source": Column("Where the row comes from: telemetry (the browser's events), server (a "
                     "page the server saw open: page_opened, tab_takeover) or trial_history "
                     "(an undo or reset press stored with its trial).", values=EVENT_SOURCES),
    "kind": Column("The event: visibility_hidden, visibility_shown, resize, clip_finished, "
                   "replay (telemetry); page_opened or tab_takeover (a page loaded, reloaded "
                   "or took the session from another tab); undo or reset (a press).",
                   values=EVENT_KINDS),
    "t_client_ms": Column("The browser's clock (epoch ms, Date.now()); for a press, the "
                          "trial's shown_at_ms + t_trial_ms.", unit="ms"),
    "t_trial_ms": Column("A press's time since its trial was shown; empty otherwise.",
                         unit="ms"),
    "received_at": Column("When the server received the event (for a press: its trial)."),
    "trial_id": Column(BANK_TRIAL_ID + "; empty when a page opened between trials."),
    "start_index": Column("The start state a press acted on, or a page's draft resumed; -1 "
                          "otherwise."),
    "clicks": Column("The clicks a page's restored draft held; -1 otherwise."),
    "replays": Column("The clip's replays so far (clip_finished, replay); -1 otherwise."),
    "w": Column("The window's inner width after a resize; -1 otherwise.", unit="CSS px"),
    "h": Column("The window's inner height after a resize; -1 otherwise.", unit="CSS px"),
}

PARTICIPANTS = {
    **SESSION, **MODELS_SHA256,
    "external_id": Column("The platform's id of the person (PROLIFIC_PID, MTurk workerId); "
                          "empty for open and pilot sessions. PERSONAL DATA: it links the "
                          "public participant_id to a platform account; this sheet is for "
                          "payment and approval, not for sharing."),
    "recruitment": RECRUITMENT,
    "outcome": OUTCOME,
    "completion_code": Column("The code the session's ending gave (empty: none)."),
    "status": Column("ended (an outcome, or completed); in_progress (consented, written "
                     "within in_progress_timeout_min); awaiting_consent (not consented, "
                     "started within consent_timeout_min); replaced (a newer attempt took "
                     "over); else stale. Depends on the time of the export.",
                     values=SESSION_STATUSES),
    "started_at": Column("When the session started."),
    "ended_at": Column("The ending's receipt, or the completion time; empty while it runs."),
    "duration_min": Column("From start to end; empty until it ends.", unit="min"),
    "last_seen": Column("The session's last write."),
    "world_order": Column("The session's worlds in the order it takes them, comma-joined."),
    "steps_done": Column("Plan steps taken (a session that declined or was screened out stops "
                         "where it ended)."),
    "steps_total": Column("The plan's length in steps."),
    "attention_checks": Column("Attention checks answered."),
    "attention_failed": Column("Attention checks failed."),
    "attention_verdict": Column("failed (a check failed: review before rejecting), passed, or "
                                "none (no check answered yet).", values=ATTENTION_VERDICTS),
    "pilot": Column("A researcher's preview session (recruitment pilot)."),
    "replaced": REPLACED,
    "prolific_check": PROLIFIC_CHECK,
    "excluded": Column("The analysis leaves the session out."),
    "exclusion_reasons": Column("Why, ;-joined: " + ", ".join(EXCLUSION_REASONS) + ".",
                                pattern=one_of(EXCLUSION_REASONS, ";")),
    "app_version": Column("The tomstudy version that served the session."),
    "screen_w": Column("The window's inner width at consent; -1 without consent.",
                       unit="CSS px"),
    "screen_h": Column("The window's inner height at consent; -1 without consent.",
                       unit="CSS px"),
    "touch_only": Column("The device had touch and no mouse at consent (false without "
                         "consent)."),
    "reduced_motion": Column("The browser asked for reduced motion at consent (false without "
                             "consent)."),
    "user_agent": Column("The browser's user agent at consent (empty without consent); with "
                         "other columns it may help identify a person."),
}

CODEBOOK = {"predictions": PREDICTIONS, "survey": SURVEY, "events": EVENTS,
            "participants": PARTICIPANTS}

# a predictor's four columns (PLUGIN_FIELDS), described for any name
PLUGIN_COLUMNS = {
    "vx": Column("{who}: the predicted robot move's x component.", unit="m/s"),
    "vy": Column("{who}: the predicted robot move's y component.", unit="m/s"),
    "code": Column("{who}: its discrete code, -1 when it has none."),
    "sha256": Column("{who}: its content hash, as the bank stores it.", pattern=SHA256),
}
COARSE = ("The coarse observer {name} (app/observers/predictor.py: its expected move from what "
          "the participant was shown; empty in rows of a bank built before the observers)")
PLUGIN = ("The plug-in predictor {name} (the study config's `predictors`; "
          "docs/extend/add-a-predictor.md)")


def export_kinds(what: str, columns) -> dict[str, str]:
    """The kind of each of an export's `columns` by its contract (plug-in columns included)."""
    if what not in WHAT:
        raise ValueError(f"what: unknown export {what!r}; choose one of {', '.join(WHAT)}")
    contract = column_kinds(columns) if what == "predictions" else SCHEMAS[what]
    unknown = [c for c in columns if c not in contract]
    if unknown:
        raise ValueError(f"columns: {', '.join(unknown)} not in the {what} export's contract")
    return {c: contract[c] for c in columns}


def column_entry(what: str, name: str, terms: StudyTerms) -> Column:
    """The codebook's entry of one column of export `what` (a plug-in's from PLUGIN_COLUMNS)."""
    entry = CODEBOOK[what].get(name)
    if entry is None:
        entry = _plugin_entry(name)
    if name == "world":
        return Column(entry.text, values=terms.worlds)
    if name == "question" and what == "survey":
        return Column(entry.text, values=terms.questions)
    if name == "world_order" and terms.worlds:
        return Column(entry.text, pattern=one_of(terms.worlds, ","))
    return entry


def _plugin_entry(name: str) -> Column:
    for field, entry in PLUGIN_COLUMNS.items():
        predictor = name.removesuffix(f"_{field}")
        if predictor != name:
            who = (COARSE if predictor in COARSE_OBSERVERS else PLUGIN).format(name=predictor)
            return Column(entry.text.format(who=who), entry.unit, entry.values, entry.pattern)
    raise KeyError(f"{name}: no codebook entry (analysis/codebook.py)")


def table_schema(what: str, columns, terms: StudyTerms = StudyTerms()) -> dict:
    """The Frictionless Table Schema of export `what` with these `columns`."""
    kinds = export_kinds(what, columns)
    return {"fields": [_field(name, kind, column_entry(what, name, terms))
                       for name, kind in kinds.items()],
            "missingValues": [""]}


def _field(name: str, kind: str, entry: Column) -> dict:
    field = {"name": name, "type": FIELD_TYPES[kind], "description": entry.text}
    if entry.unit:
        field["unit"] = entry.unit
    if kind == "bool":
        field |= {"trueValues": ["True"], "falseValues": ["False"]}
    constraints = {"required": True} if entry.required else {}
    if entry.values:
        constraints["enum"] = list(entry.values)
    if entry.pattern:
        constraints["pattern"] = entry.pattern
    return field | ({"constraints": constraints} if constraints else {})


def data_package(what: str, columns, csv: bytes, path: str, rows: int, study_id: str,
                 hashes: dict[str, list[str]], terms: StudyTerms = StudyTerms()) -> dict:
    """The Data Package describing one export CSV (`csv`, its bytes, saved as `path` beside
    the package): its schema, sha256, size and row count, the export version and the
    study's config, bank and model hashes as its rows carry them (`hashes`, STUDY_VERSION)."""
    missing = [key for key in STUDY_VERSION if key not in hashes]
    if missing:
        raise ValueError(f"hashes: missing {', '.join(missing)}")
    return {
        "profile": "tabular-data-package",
        "name": re.sub(r"[^a-z0-9.-]", "-", f"{study_id}-{what}".lower()),
        "title": f"tomstudy {what} export of study {study_id}",
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "export_version": EXPORT_VERSION,
        "study_id": study_id,
        "study_hashes": {key: sorted(hashes[key]) for key in STUDY_VERSION},
        "resources": [{
            "name": what, "path": path, "profile": "tabular-data-resource",
            "format": "csv", "mediatype": "text/csv", "encoding": "utf-8",
            "bytes": len(csv), "hash": "sha256:" + sha256_bytes(csv),
            "rows": rows,
            "description": _resource_note(what),
            "dialect": {"delimiter": ",", "quoteChar": '"', "doubleQuote": True,
                        "header": True},
            "schema": table_schema(what, columns, terms),
        }],
    }


def _resource_note(what: str) -> str:
    kinds = "; ".join(f"{FIELD_TYPES[k]}: {note}" for k, note in KIND_NOTES.items())
    return (f"The {what} export (app/http/API.md, Exports). Cells: {kinds}. A text cell "
            "that would start a spreadsheet formula (=, +, -, @, tab, carriage return) or "
            "starts with ' is written with one leading ' (analysis.exports.read_export "
            "removes it).")
