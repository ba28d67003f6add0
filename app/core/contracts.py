"""The contracts the study server and the analysis share: one definition each.

- the export columns and their types (predictions, survey, events, participants);
- the exclusion rules a study config names and the analysis applies;
- how the figures and the researcher dashboard name and colour each model (and plug-in).
- what the analysis takes from a study besides its rows (`StudyInputs`).

The metric itself, alignment error, is in app/core/alignment.py. Both `app` and `analysis`
import this module; it imports neither, so the packages depend one way. Only numpy and
pydantic.
"""

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

# Every export's first column, export_version: 1 = before the rename below (an export without
# the column), 2 = the participant's answer renamed (RENAMED_COLUMNS).
EXPORT_VERSION = 2
# export_version 2's renames, an older export's name -> the current one; the database keeps the
# old names (the person agent's position stays human_x, human_y)
RENAMED_COLUMNS = {"human_vx": "participant_vx", "human_vy": "participant_vy",
                   "click_x": "participant_click_x", "click_y": "participant_click_y"}
STORED_NAMES = {new: old for old, new in RENAMED_COLUMNS.items()}  # export -> database name

# Export contract, in order. Types: the reader casts to these, so CSV and DB agree.
STRING_COLUMNS = ("study_id", "participant_id", "recruitment", "outcome", "prolific_check", "world",
                  "trial_id", "arm", "clip_sha256", "start_kind", "ours_sha256", "vae_sha256",
                  "click_input", "submission_id", "submitted_at", "config_sha256", "bank_sha256")
BOOL_COLUMNS = ("completed", "replaced", "attention_passed", "is_practice", "attention_check")
INT_COLUMNS = ("export_version", "world_position", "trial_index", "start_index", "step",
               "ours_code", "vae_code", "replays")
FLOAT_COLUMNS = ("start_x", "start_y", "human_x", "human_y", "participant_click_x",
                 "participant_click_y", "participant_vx", "participant_vy", "ours_vx", "ours_vy",
                 "vae_vx", "vae_vy", "cv_vx", "cv_vy", "policy_vx", "policy_vy", "click_time_ms",
                 "trial_duration_ms")
EXPORT_COLUMNS = (
    "export_version", "study_id", "participant_id", "recruitment", "completed", "outcome",
    "replaced", "prolific_check", "attention_passed", "world", "world_position", "trial_id",
    "trial_index", "is_practice", "attention_check", "arm", "clip_sha256", "start_index",
    "start_kind", "step",
    "start_x", "start_y", "human_x", "human_y", "participant_click_x", "participant_click_y",
    "participant_vx", "participant_vy", "ours_vx", "ours_vy", "vae_vx", "vae_vy", "cv_vx",
    "cv_vy", "policy_vx", "policy_vy", "ours_code", "vae_code", "ours_sha256", "vae_sha256",
    "click_time_ms", "click_input", "trial_duration_ms", "replays", "submission_id",
    "submitted_at", "config_sha256", "bank_sha256",
)
# Each plug-in predictor of a study (app/predictors/) adds these columns, in the study config's
# order after the contract's, named <predictor>_<field>; a plug-in's code is -1 when it has none
PLUGIN_FIELDS = {"vx": "float", "vy": "float", "code": "int", "sha256": "text"}


def plugin_columns(name: str) -> list[str]:
    """The export columns of plug-in predictor `name`."""
    return [f"{name}_{field}" for field in PLUGIN_FIELDS]


def plugin_names(columns) -> list[str]:
    """The plug-in predictors whose columns are all among `columns`, in the order they appear
    (Ours, the VAE, constant velocity and the policy are the contract's own)."""
    present = set(columns)
    names = [c[: -len("_sha256")] for c in columns if c.endswith("_sha256")]
    return [n for n in names if n not in MODELS and present.issuperset(plugin_columns(n))]


def column_kinds(columns) -> dict[str, str]:
    """Every predictions export column among `columns` and its kind (text, bool, int or
    float): the contract's, then each plug-in predictor's."""
    kinds = {c: ("text" if c in STRING_COLUMNS else "bool" if c in BOOL_COLUMNS
                 else "int" if c in INT_COLUMNS else "float") for c in EXPORT_COLUMNS}
    for name in plugin_names(columns):
        kinds |= dict(zip(plugin_columns(name), PLUGIN_FIELDS.values(), strict=True))
    return kinds


# columns added after the first export, with the value an older export's rows read as
ADDED_COLUMNS = {"arm": "", "replaced": False, "click_input": "", "export_version": 1,
                 "prolific_check": "",
                 "screen_w": -1, "screen_h": -1, "touch_only": False, "reduced_motion": False,
                 "user_agent": ""}
SORT_KEYS = ["participant_id", "trial_index", "trial_id", "start_index", "step"]

# Every export except predictions (whose rows carry each model's hash already) names
# the models a session's answers came from as JSON: {"<world>": {"ours": sha, "vae": sha}}.
STUDY_VERSION = {"config_sha256": "text", "bank_sha256": "text", "models_sha256": "text"}
VERSIONED = {"export_version": "int"}  # EXPORT_VERSION, first in every export

SURVEY = {
    **VERSIONED, "study_id": "text", "participant_id": "text", "question": "text", "kind": "text",
    "answer": "text", "answered_at": "time", **STUDY_VERSION,
}
EVENTS = {
    **VERSIONED, "study_id": "text", "participant_id": "text", "source": "text", "kind": "text",
    "t_client_ms": "float", "t_trial_ms": "float", "received_at": "time",
    "trial_id": "text", "start_index": "int", "clicks": "int", "replays": "int", "w": "int",
    "h": "int",
    **STUDY_VERSION,
}
# The device a session consented from (stored with consent, never before): the window's
# inner size in CSS px (-1 and empty text when no consent was given), the browser's user agent
# and its reduced-motion preference.
DEVICE = {"screen_w": "int", "screen_h": "int", "touch_only": "bool", "reduced_motion": "bool",
          "user_agent": "text"}
PARTICIPANTS = {
    **VERSIONED, "study_id": "text", "external_id": "text", "recruitment": "text",
    "participant_id": "text", "outcome": "text", "completion_code": "text",
    "status": "text", "started_at": "time", "ended_at": "time", "duration_min": "float",
    "last_seen": "time", "world_order": "text", "steps_done": "int", "steps_total": "int",
    "attention_checks": "int", "attention_failed": "int", "attention_verdict": "text",
    "pilot": "bool", "replaced": "bool", "prolific_check": "text", "excluded": "bool",
    "exclusion_reasons": "text",
    "app_version": "text", **DEVICE, **STUDY_VERSION,
}
SCHEMAS = {"survey": SURVEY, "events": EVENTS, "participants": PARTICIPANTS}
WHAT = ("predictions", *SCHEMAS)

MODELS = ("ours", "vae", "cv", "policy")
# the coarse observers the bank stores beside the models (app/observers/predictor.py), exported
# as plug-in columns; the family's precise observer is `policy`, its constant velocity `cv`
COARSE_OBSERVERS = ("coarse", "coarse_scene", "coarse_momentum")
# Okabe-Ito, safe for colour-blind readers; `human` is the participants' answers
MODEL_COLORS = {"ours": "#E69F00", "vae": "#0072B2", "cv": "#009E73", "policy": "#CC79A7",
                "human": "#000000", "coarse": "#661100", "coarse_scene": "#6699CC",
                "coarse_momentum": "#888888"}  # the observers' from Paul Tol's sets, no plug-in's
MODEL_LABELS = {"ours": "Ours", "vae": "VAE", "cv": "Const. vel.", "policy": "Policy",
                "human": "Participants", "coarse": "Coarse observer",
                "coarse_scene": "Coarse, scene", "coarse_momentum": "Coarse, momentum"}
# plug-in predictors' colours: the rest of Okabe-Ito, then Paul Tol's muted set
PLUGIN_COLORS = ("#D55E00", "#56B4E9", "#882255", "#44AA99", "#117733", "#999933", "#AA4499",
                 "#332288")


def model_color(name: str) -> str:
    """A predictor's colour: the study's own from MODEL_COLORS; a plug-in's picked from
    PLUGIN_COLORS by the SHA-256 of its name, so it is the same in every study and figure."""
    if name in MODEL_COLORS:
        return MODEL_COLORS[name]
    digest = hashlib.sha256(name.encode()).digest()
    return PLUGIN_COLORS[int.from_bytes(digest[:4], "big") % len(PLUGIN_COLORS)]


def model_label(name: str) -> str:
    """A predictor's label: the study's own from MODEL_LABELS; a plug-in's is its registered
    name, the prefix of its export columns."""
    return MODEL_LABELS.get(name, name)


def model_style(names) -> dict[str, dict[str, str]]:
    """Colours and labels of `names` (and the people's), as the dashboard draws them."""
    names = [*names, "human"]
    return {"colors": {n: model_color(n) for n in names},
            "labels": {n: model_label(n) for n in names}}

PILOT = "pilot"  # the recruitment of a researcher's preview session
# a session's prolific_check values Prolific has not confirmed: it answered it does not know the
# submission, or it could not be asked since the session started (app/server/flow/prolific_check.py)
PROLIFIC_UNCONFIRMED = ("unknown", "pending")

# The study config's `smallest_effect_of_interest` unless it sets one, in alignment-error units:
# an Ours - VAE difference in mean alignment error within +-0.005 is treated as no difference.
# It lies below the smallest difference either observer account predicts where the design goal
# is met (Highway pilots, family, primary test: coarse -0.0070, precise +0.0104;
# docs/reproduce/instrument.md, "The design goal"), so a difference this small supports neither
# account.
SMALLEST_EFFECT_OF_INTEREST = 0.005


class ExclusionRules(BaseModel):
    """Named exclusion rules, the study config's `exclusions` section (same keys).

    A participant is excluded for a failed attention check, an incomplete session, or
    more than `too_fast_max_fraction` of scored trials answered within `too_fast_trial_ms`;
    of the participants kept, single too-fast trials are dropped.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    # true: a participant who failed an attention check is excluded from the analysis
    failed_attention_check: bool = True
    # true: a participant who did not complete the study is excluded
    incomplete: bool = True
    # a scored trial answered in less than this many milliseconds (>= 0) is too fast: dropped from
    # the analysis of a kept participant
    too_fast_trial_ms: float = Field(default=4000.0, ge=0)
    # a participant with more than this share (0-1) of scored trials too fast is excluded
    too_fast_max_fraction: float = Field(default=0.25, ge=0, le=1)

    def too_fast(self, duration_ms):
        """Where a trial's duration [ms] is under the limit (numbers, arrays or SQL columns)."""
        return duration_ms < self.too_fast_trial_ms


def too_fast_share_exceeds(n_fast, n_trials, rules: ExclusionRules) -> np.ndarray:
    """Where more than the rules' share of a participant's scored trials were too fast
    (elementwise over counts; False without trials)."""
    n_fast = np.asarray(n_fast, dtype=np.float64)
    n_trials = np.asarray(n_trials, dtype=np.float64)
    share = np.where(n_trials > 0, n_fast / np.maximum(n_trials, 1.0), 0.0)
    return share > rules.too_fast_max_fraction


@dataclass(frozen=True)
class StudyInputs:
    """What the analysis takes from the study besides its rows, as plain values and paths."""

    config: dict  # the study config as plain data, recorded in meta.json
    rules: ExclusionRules
    models: dict  # the bundle manifest's {world: {model: {seed (str): content_hash}}}
    bank: Path  # the trial bank (bank.json or a bundle's bank.json.gz; may be absent): every
    #             seed's answers and each world's scene
