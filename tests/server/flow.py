"""A participant driven through the real HTTP API (any httpx-like client)."""

import dataclasses
import hashlib
import json
import re
import uuid
from dataclasses import dataclass

import numpy as np
from fastapi.testclient import TestClient

from app.main import create_app
from app.pilot.bots import segment_key
from app.server.flow.plan import PART_PHASES, TRIAL_PHASES
from app.server.flow.sessions import SESSION_HEADER, SESSION_PATH
from tests.conftest import ADMIN_TOKEN, REPO, local_client

TOKEN = ADMIN_TOKEN
ADMIN = {"Authorization": f"Bearer {TOKEN}"}
JS = REPO / "frontend" / "static" / "js"
DEVICE = {"screen_w": 1600, "screen_h": 900, "touch_only": False, "user_agent": "pytest"}


def new_id() -> str:
    """A fresh client submission UUID."""
    return str(uuid.uuid4())


def straight_clicks(trial: dict, direction_rad: float | None = None) -> list:
    """Three equal mid-reach moves per start state, in a direction that stays in the scene.

    With `direction_rad` given, that direction is tried first (attention checks).
    """
    b = trial["scene"]["bounds"]
    reach = (trial["min_step_m"] + trial["max_step_m"]) / 2
    n = trial["steps_to_predict"]
    points = []
    for start in trial["start_states"]:
        x, y = start["robot"]
        angles = np.deg2rad(np.arange(0, 360, 15))
        if direction_rad is not None:
            angles = np.concatenate([[direction_rad], angles])
        for a in angles:
            path = [[x + reach * k * np.cos(a), y + reach * k * np.sin(a)] for k in range(1, n + 1)]
            if all(b["x_min_m"] <= px <= b["x_max_m"] and b["y_min_m"] <= py <= b["y_max_m"]
                   for px, py in path):
                points.append([[float(px), float(py)] for px, py in path])
                break
    return points


def prediction_body(trial: dict, points: list | None = None, duration_ms: float = 8000) -> dict:
    """A valid prediction submission for `trial`: mouse clicks spread over the client's
    duration."""
    points = points if points is not None else straight_clicks(trial)
    k, n = len(trial["start_states"]), trial["steps_to_predict"]
    gap = duration_ms / (k * n + 1)
    return {"submission_id": new_id(), "trial_id": trial["trial_id"], "points": points,
            "click_times_ms": [[gap * (i * n + j + 1) for j in range(n)] for i in range(k)],
            "click_inputs": [["mouse"] * n for _ in range(k)],
            "shown_at_ms": 1000.0, "submitted_at_ms": 1000.0 + duration_ms, "replays": 1}


def draft_body(trial: dict, clicks: int = 2, seq: int = 1) -> dict:
    """A draft of `trial` (PUT .../draft): `clicks` of its first start state's straight moves,
    by mouse."""
    first = straight_clicks(trial)[0][:clicks]
    rest = [[] for _ in trial["start_states"][1:]]
    return {"trial_id": trial["trial_id"], "seq": seq, "index": 0, "points": [first, *rest],
            "click_times_ms": [[1000.0 * (j + 1) for j in range(clicks)], *rest],
            "click_inputs": [["mouse"] * clicks, *rest],
            "history": [], "shown_at_ms": 1000.0, "replays": 0}


def prolific(name: str) -> dict:
    """Valid Prolific URL parameters for a participant called `name` (one attempt)."""
    return {"PROLIFIC_PID": hex24(name), "STUDY_ID": hex24("study"),
            "SESSION_ID": f"s-{hex24(name)[:8]}"}


def hex24(name: str) -> str:
    """A Prolific-shaped id (24 hex characters) derived from `name`."""
    return hashlib.sha256(name.encode()).hexdigest()[:24]


def bank_trial(bank: dict, payload: dict) -> dict:
    """The bank record of the trial a browser payload shows (the payload's id is opaque)."""
    return bank[segment_index(bank)[segment_key(payload["segment"]["positions"])]]


def segment_index(bank: dict) -> dict:
    """segment_key -> bank trial id."""
    return {segment_key(t["segment"]["positions"]): tid for tid, t in bank.items()}


@dataclass
class Participant:
    """One participant's session on a server."""

    client: object
    study_id: str
    token: str = ""
    status: int = 0

    def start(self, preview: str | None = None, **recruitment) -> dict:
        """POST /api/sessions (no parameters: a fresh valid Prolific participant)."""
        if not recruitment and preview is None:
            recruitment = prolific(new_id())
        body = {"study_id": self.study_id, "recruitment": recruitment}
        if preview is not None:
            body["preview"] = preview
        r = self.client.post("/api/sessions", json=body)
        self.status = r.status_code
        body = r.json()
        self.token = body.get("session_token", "")
        return body

    def url(self, what: str) -> str:
        """Path of one of this session's routes (the token goes in `headers`)."""
        return f"{SESSION_PATH}/{what}"

    @property
    def headers(self) -> dict:
        """The header that names this session."""
        return {SESSION_HEADER: self.token}

    def get(self, what: str):
        """GET one of this session's routes; returns the response."""
        return self.client.get(self.url(what), headers=self.headers)

    def state(self) -> dict:
        """GET .../state."""
        r = self.get("state")
        assert r.status_code == 200, r.text
        return r.json()

    def post(self, what: str, body: dict, **kwargs):
        """POST a step (or `content=` raw bytes); returns the response."""
        if "content" not in kwargs:
            kwargs["json"] = body
        headers = self.headers | kwargs.pop("headers", {})
        return self.client.post(self.url(what), headers=headers, **kwargs)

    def put(self, what: str, body: dict, headers: dict | None = None):
        """PUT to one of this session's routes (a draft); returns the response."""
        return self.client.put(self.url(what), json=body, headers=self.headers | (headers or {}))

    def consent(self):
        """POST consent with the device info; returns the response."""
        return self.post("consent", {"submission_id": new_id(), "agree": True, "client": DEVICE})

    def pass_intro(self) -> dict:
        """Consent, instructions and the first part's introduction: at the practice trial."""
        assert self.consent().status_code == 200
        r = self.post("instructions", {"submission_id": new_id()})
        assert r.status_code == 200, r.text
        return self.pass_screens()

    def pass_screens(self) -> dict:
        """Continue through part screens (a world's introduction, practice over); the state
        after them."""
        state = self.state()
        while state["phase"] in PART_PHASES:
            r = self.post("continue", {"submission_id": new_id(), "phase": state["phase"]})
            assert r.status_code == 200, r.text
            state = r.json()
        return state

    def answer_trial(self, bank: dict | None = None, duration_ms: float = 8000) -> dict:
        """Answer the next trial (attention checks along the robot's true first move)."""
        trial = self.pass_screens()["step"]
        points = straight_clicks(trial)
        record = bank_trial(bank, trial) if bank is not None else None
        if record is not None and record["kind"] == "attention":
            truth = record["policy_actions"]
            points = [straight_clicks(_one(trial, i), float(np.arctan2(t[0][1], t[0][0])))[0]
                      for i, t in enumerate(truth)]
        body = prediction_body(trial, points, duration_ms)
        r = self.post("predictions", body)
        assert r.status_code == 201, r.text
        return r.json()

    def save_draft(self, clicks: int = 2, seq: int = 1):
        """PUT a draft of the next trial: `clicks` straight clicks from its first start state."""
        trial = self.pass_screens()["step"]
        return self.put("draft", draft_body(trial, clicks, seq))

    def survey(self, strategy: str = "followed the lanes") -> dict:
        """POST the closing survey (`strategy` as the free-text answer); the answered state."""
        r = self.post("survey", {"submission_id": new_id(),
                                 "answers": {"difficulty": 4, "confidence": 5, "driving": "yes",
                                             "strategy": strategy}})
        assert r.status_code == 200, r.text
        return r.json()

    def finish(self, bank: dict | None = None, duration_ms: float = 8000,
               strategy: str = "followed the lanes") -> dict:
        """Answer every remaining trial and the survey."""
        while self.pass_screens()["phase"] in TRIAL_PHASES:
            self.answer_trial(bank, duration_ms)
        return self.survey(strategy)


def fail_attention_checks(p: Participant, bank: dict) -> None:
    """Answer every trial; attention checks against the robot's plain move."""
    while p.pass_screens()["phase"] in TRIAL_PHASES:
        trial = p.state()["step"]
        record = bank_trial(bank, trial)
        points = straight_clicks(trial)
        if record["kind"] == "attention":
            points = [straight_clicks(dict(trial, start_states=[s]),
                                      float(np.arctan2(-t[0][1], -t[0][0])))[0]
                      for s, t in zip(trial["start_states"], record["policy_actions"],
                                      strict=True)]
        assert p.post("predictions", prediction_body(trial, points)).status_code == 201


def start(client, study_id: str, preview: str | None = None, **params):
    """POST /api/sessions with exactly these recruitment `params`; returns the response."""
    body = {"study_id": study_id, "recruitment": params}
    if preview is not None:
        body["preview"] = preview
    return client.post("/api/sessions", json=body)


def with_config(client, study_id: str, **updates) -> None:
    """Serve `study_id` with these top-level config keys replaced (the app's loaded context)."""
    ctx = client.app.state.studies[study_id]
    config = ctx.config.model_copy(update=updates)
    client.app.state.studies[study_id] = dataclasses.replace(ctx, config=config)


def with_recruitment(client, study_id: str, **changes) -> None:
    """Serve `study_id` with its recruitment section changed."""
    recruitment = client.app.state.studies[study_id].config.recruitment.model_copy(
        update=changes)
    with_config(client, study_id, recruitment=recruitment)


def with_cap(client, study_id: str, per_target: float, target: int) -> None:
    """Serve `study_id` with max_live_sessions_per_target x target_sample_size changed."""
    with_config(client, study_id, max_live_sessions_per_target=per_target,
                target_sample_size=target)


def at_first_trial(client, study_id: str, **recruitment) -> Participant:
    """A participant past consent and instructions, at the practice trial."""
    p = Participant(client, study_id)
    p.start(**recruitment)
    p.pass_intro()
    return p


def _one(trial: dict, i: int) -> dict:
    return dict(trial, start_states=[trial["start_states"][i]])


def make_client(small_study, db_url: str, trust_client_clock: bool = True) -> TestClient:
    """A TestClient of a fresh app on `db_url` (lifespan runs on enter).

    It trusts the client's clock by default: these tests answer in milliseconds while
    claiming human durations (test_public_server checks the server's own clock).
    """
    settings = small_study.settings(db_url, trust_client_clock=trust_client_clock)
    return local_client(create_app(settings, [small_study.study_id]))


def served_codes(study, study_id: str | None = None) -> dict[str, str]:
    """Each outcome's completion code a server of `study` gives (its generated codes, made in
    its data dir on first use, or the config's pinned ones)."""
    from app.configio import load_yaml_model
    from app.server.flow.completion_codes import OUTCOMES, served_config
    from app.study.config import StudyConfig

    study_id = study_id or study.study_id
    config = load_yaml_model(study.configs_dir / f"{study_id}.yaml", StudyConfig)
    recruitment = served_config(config, study.layout, study_id).recruitment
    return {outcome: recruitment.ending(outcome).completion_code for outcome in OUTCOMES}


def page_json(html: str, element_id: str):
    """What a page carries in its `<script type="application/json" id=element_id>`."""
    block = re.search(rf'<script type="application/json" id="{element_id}">(.*?)</script>',
                      html, re.S)
    assert block, f"no #{element_id} on the page"
    return json.loads(block.group(1))


def participant_scripts(entry: str = "app.js") -> dict[str, str]:
    """The study page's scripts by name: `entry` and every module it imports, however deep."""
    scripts, wanted = {}, [entry]
    while wanted:
        name = wanted.pop()
        if name not in scripts:
            scripts[name] = (JS / name).read_text()
            wanted += re.findall(r'from "\./([\w-]+\.js)";', scripts[name])
    return scripts
