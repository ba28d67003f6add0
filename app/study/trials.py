"""The trial bank: clips, start states and every predictor's answers, built once per study.

Stored at app.layout's `bank` (+ `bank_meta` with input hashes). Per world the bank
holds the scene, dt, the click limits and a list of trials of three kinds: `main` (the
pool balanced assignment draws from), `practice` and `attention`.

Shape legend per trial: E examples, L segment steps, K start states, n steps to predict.
- examples[e].positions [len+1, 2, 2], segment.positions [L+1, 2, 2] (m; robot first)
- start_states[k].robot / .human [2] (m); the human stays at its segment-end position;
  start_states[k].start_kind says where the robot start came from (`own` first)
- model_input [T+1, 2, 2] (m): what every model read, the latest T steps ending at the
  segment's end (T = the checkpoints' segment_len; it may reach back before the shown segment)
- predictions[model][s].actions, cv_actions, policy_actions [K, n, 2] (m/s); predictions holds
  one answer per seed of the study's model family (ours, vae), the primary seed first, then one
  answer (seed NO_SEED) per coarse observer (app/observers/predictor.py) and per plug-in
  predictor of the study config (app/predictors/)
"""

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from app.configio import StrictModel, omitted_when_empty
from app.core.files import json_sha256, read_bytes, sha256_bytes
from app.layout import Layout

# what the participant is shown, and so what every model and baseline answers from
POS_DECIMALS = 3  # positions in m
HEADING_DECIMALS = 4  # headings in rad
SIZE_DECIMALS = 2  # agents' lengths and widths in m
NO_SEED = -1  # the seed of a plug-in predictor's answer: code, not a trained checkpoint


class Clip(StrictModel):
    """An animation: positions [steps+1, 2, 2] and headings [steps+1, 2]; `sizes` [2, 2] m,
    each agent's (length, width) as recorded (a recorded world's; left out of the bank and
    the page where absent, so a simulated world's clips keep their bytes and hashes)."""

    positions: list[list[list[float]]]
    headings: list[list[float]]
    robot_label: int | None = None
    source_index: int | None = None
    sizes: list[list[float]] | None = None

    _without_unset_sizes = omitted_when_empty("sizes")

    def shown(self) -> dict:
        """What the page draws of the clip: positions, headings and (when known) sizes."""
        return self.model_dump(include={"positions", "headings", "sizes"})


class StartState(StrictModel):
    """Where the robot starts one prediction; the human is fixed.

    `start_kind`: `own` (the robot's segment end), or how a data-covered start relates to
    it (Highway `same_lane` / `adjacent_lane`, Obstacle `near` / `mid`); banks built
    before issue 22 also have `offset` (a step beside or behind the robot, their attention
    checks). See app/bank/start_states.py.
    """

    robot: list[float]
    human: list[float]
    robot_heading: float
    human_heading: float
    robot_speed: float
    start_kind: str


class ModelAnswer(StrictModel):
    """One predictor's reading of the segment and its actions [K, n, 2]: a checkpoint's (model
    and seed), or a plug-in's (seed NO_SEED; code -1 and z [] when it has none)."""

    seed: int
    z: list[float]
    code: int
    actions: list[list[list[float]]]
    content_hash: str


class TrialRecord(StrictModel):
    """One trial as stored in the bank (model predictions never leave the server)."""

    trial_id: str
    world: str
    kind: str  # main, practice or attention
    arm: str = ""  # main trials: how they were chosen, random or models_disagree
    source_index: int
    segment_start: int
    robot_label: int
    examples: list[Clip]
    segment: Clip
    start_states: list[StartState]
    model_input: list[list[list[float]]]
    predictions: dict[str, list[ModelAnswer]]  # predictor -> one answer per seed, primary first
    cv_actions: list[list[list[float]]]
    policy_actions: list[list[list[float]]]
    clip_sha256: str

    def primary(self, model: str) -> ModelAnswer:
        """The primary seed's answer of `model` (what the live export and dashboard show)."""
        return self.predictions[model][0]

    def primaries(self) -> dict[str, ModelAnswer]:
        """Every predictor's primary answer (checkpoints' primary seed, each plug-in's one)."""
        return {name: family[0] for name, family in self.predictions.items()}

    def browser_payload(self) -> dict:
        """What the participant's browser needs to play and ask this trial."""
        return {
            "examples": [c.shown() for c in self.examples],
            "segment": self.segment.shown(),
            "start_states": [s.model_dump(exclude={"robot_speed", "start_kind"})
                             for s in self.start_states],
        }


class WorldBank(StrictModel):
    """One world's scene, click limits and trials."""

    world: str
    dt_s: float
    scene: dict
    robot_label_name: str
    label_names: list[str]
    max_step_m: float
    min_step_m: float
    trials: list[TrialRecord]


class BankFile(StrictModel):
    """The whole bank.json."""

    study_id: str
    steps_to_predict: int
    worlds: dict[str, WorldBank]


def clip_sha256(scene: dict, dt_s: float, payload: dict) -> str:
    """SHA-256 of exactly what a participant is shown (canonical JSON)."""
    shown = {"scene": scene, "dt_s": dt_s, **payload}
    return json_sha256(shown)


@dataclass
class TrialBank:
    """Read-only lookup over a loaded bank."""

    data: BankFile
    sha256: str

    @classmethod
    def load(cls, layout: Layout, study_id: str) -> "TrialBank":
        """Read the study's working bank.json (trials/<study>/, what build-trials wrote; a
        server reads its bundle's); FileNotFoundError says how to build it."""
        path = layout.bank(study_id)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no trial bank; run `tomstudy build-trials "
                                    f"--study {study_id}`")
        return cls.read(path)

    @classmethod
    def read(cls, path: Path) -> "TrialBank":
        """A bank file (bank.json, or a bundle's bank.json.gz); its sha256 is of the JSON."""
        return cls.parse(read_bytes(path))

    @classmethod
    def parse(cls, raw: bytes) -> "TrialBank":
        """A bank from its JSON bytes (validated); its sha256 is of those bytes."""
        return cls(BankFile.model_validate_json(raw), sha256_bytes(raw))

    @cached_property
    def by_id(self) -> dict[str, TrialRecord]:
        """Every trial by its id."""
        return {t.trial_id: t for w in self.data.worlds.values() for t in w.trials}

    @cached_property
    def code_predictors(self) -> list[str]:
        """The predictors besides Ours and the VAE whose answers the bank stores, in stored
        order: the coarse observers (none in a bank built before them), the plug-ins."""
        first = next(iter(self.by_id.values()))
        return [name for name in first.predictions if name not in ("ours", "vae")]

    def world(self, name: str) -> WorldBank:
        """The bank of one world."""
        return self.data.worlds[name]

    def trials_of(self, world: str, kind: str) -> list[TrialRecord]:
        """A world's trials of one kind, in bank order."""
        return [t for t in self.world(world).trials if t.kind == kind]
