"""The typed study definition (study_configs/<study>.yaml): text, design, recruitment, models."""

import math
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, ValidationError, field_validator, model_validator

from app.configio import (
    ConfigError,
    StrictModel,
    load_yaml_model,
    omitted_when,
    omitted_when_default,
    omitted_when_empty,
)
from app.core.contracts import COARSE_OBSERVERS, SMALLEST_EFFECT_OF_INTEREST, ExclusionRules
from app.core.files import json_sha256
from app.predictors.registry import check_names
from app.settings import Settings
from app.study.words import DEFAULT_DEMO, DemoName, ParticipantWords

# a simulated world (app/worlds/registry.py SIMULATED_WORLDS) or a recorded one:
# study_configs/worlds/<name>.yaml
WorldName = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,31}$")]
# where a study's frozen bundle is (app/bank/bundle.py): `shipped` in the configs dir (in git,
# served as it is), `built` in the data dir (made by `tomstudy bundle build`)
BundleSource = Literal["shipped", "built"]


class SegmentSteps(StrictModel):
    """How many steps of the partial interaction a participant watches (inclusive range)."""

    # fewest steps of the partial interaction a trial shows (>= 2); each bank segment's length is
    # drawn uniformly from min..max, so changing it rebuilds the bank
    min: int = Field(ge=2)
    # most steps a trial shows (>= min); a longer segment shows the participant more of the
    # interaction before they predict
    max: int = Field(ge=2)

    @model_validator(mode="after")
    def _ordered(self) -> "SegmentSteps":
        if self.max < self.min:
            raise ValueError("max must be >= min")
        return self


class AttentionChecks(StrictModel):
    """Trials that catch inattention and never reject an attentive person.

    Their start states follow the main trials' rule (so their geometry gives nothing
    away). A participant passes one if, in at least `min_passing_starts` of the start
    states, the first clicked move is within `max_angle_deg` of the world policy's first
    move. The bank (app/bank/attention.py) keeps the segments that constant velocity fails
    (going straight on is not enough) and that every attentive observer of the family
    passes with probability >= `min_attentive_pass_rate` at the view's click noise; where
    none is both, the fairest, and meta.json says the rule was not met. So the angle, the
    passing starts and the pass rate shape the bank: a check is fair at its own threshold.
    `candidate_max_angle_deg` is retired (issue 30): no rule reads it; it is accepted so
    configs and bundles written before still validate.
    """

    # attention check trials per world in each participant's plan (0: none); the bank holds this
    # many checks per world
    per_world: int = Field(default=1, ge=0)
    # a start state passes when the first clicked move is within this angle (degrees, 0-180] of the
    # world policy's first move; larger is more lenient
    max_angle_deg: float = Field(default=45.0, gt=0, le=180)
    # start states of a check that must pass for the check to pass (1..start_states)
    min_passing_starts: int = Field(default=4, ge=1)
    # retired (issue 30): read by no rule; accepted (degrees, 0-180] so older configs and bundles
    # validate
    candidate_max_angle_deg: float = Field(default=15.0, gt=0, le=180)
    # the probability (0-1] with which every attentive simulated observer of the family must pass
    # a segment for the bank to pick it as a check; higher asks for easier checks
    min_attentive_pass_rate: float = Field(default=0.95, gt=0, le=1)

    # a config at the default rate dumps as before the key existed (same config hash)
    _without_default_rate = omitted_when_default("min_attentive_pass_rate")


class SurveyQuestion(StrictModel):
    """One closing question; likert answers are integers in [scale_min, scale_max]."""

    # the answer's column name in the exports: lower case letters, digits and _, unique in the
    # survey
    key: str = Field(pattern=r"^[a-z][a-z0-9_]*$")
    # the question as the participant reads it
    text: str
    # `likert`: a whole number on scale_min..scale_max; `choice`: one of `options`; `text`: free
    # text of at most max_chars
    kind: Literal["likert", "text", "choice"]
    # true: the survey cannot be sent without an answer (422 naming the question); false: it may be
    # left empty
    required: bool = True
    # likert only: the lowest answer accepted
    scale_min: int = 1
    # likert only: the highest answer accepted
    scale_max: int = 7
    # choice only: the answers offered; any other answer is refused
    options: list[str] = []
    # the longest answer accepted, in characters (>= 1); a longer one is refused
    max_chars: int = Field(default=2000, ge=1)


class Ending(StrictModel):
    """One way a session ends: the code the participant is given and what the page says.

    On Prolific each code is a completion code of the study with its own action (approve
    and pay, manual review, request a return, screen-out payment); '' means no code and no
    redirect, only the message.
    """

    # the code this ending gives the participant and puts in the redirect URL (letters, digits, _
    # and -, at most 64); '' = no code of its own (see Endings for the fallback)
    completion_code: str = Field(default="", max_length=64, pattern=r"^[A-Za-z0-9_-]*$")
    # what the closing page says for this ending
    message: str = ""


class Endings(StrictModel):
    """The endings besides `completed` (whose code is `recruitment.completion_code`).

    `failed_checks` is the completed study with at least `min_failed` failed attention
    checks: Prolific lets a researcher reject only after two failed checks (in a study of
    five minutes or more), so these sessions are marked for manual review, not rejected;
    its code '' means the completed code. `excluded` is a completed study that the
    study's `exclusions` remove (too many too-fast trials, or a failed check under
    `failed_attention_check`) without `min_failed` failed checks: the study chooses its
    code, '' meaning failed_checks' (review, never the approve code by default). Declined
    consent and device screen-outs end before any trial.
    """

    # a completed study with at least min_failed failed attention checks (marked for manual review);
    # code '' = the completed code
    failed_checks: Ending = Ending(message="Thank you. Your submission will be reviewed "
                                           "by the researchers.")
    # failed attention checks (>= 1) that make a completed session end as failed_checks; Prolific
    # allows a rejection only from 2
    min_failed: int = Field(default=2, ge=1)
    # a completed study the `exclusions` rules remove without min_failed failed checks; code '' =
    # failed_checks' code
    excluded: Ending = Ending(message="Thank you. Your submission will be reviewed by the "
                                      "researchers.")
    # the participant declined consent: the study ends before any trial
    declined_consent: Ending = Ending(message="You chose not to take part. Please return "
                                              "the study on the recruiting platform so "
                                              "that your place goes to someone else.")
    # the page found a device that cannot run the study (e.g. no mouse or touchpad): the study
    # ends before any trial
    screened_out: Ending = Ending(message="This study needs a laptop or desktop computer "
                                          "with a mouse or touchpad. Please return the "
                                          "study on the recruiting platform.")


class HourlyPay(StrictModel):
    """What the study pays per hour; the advertised pay is this times the estimated time
    (app/study/estimate.py)."""

    # pay per hour in `currency` (0-1000]; the advertised pay is this times the estimated duration
    amount: float = Field(gt=0, le=1000)
    currency: str = Field(pattern=r"^[A-Z]{3}$")  # ISO 4217, e.g. GBP, USD, EUR


MTURK_SUBMIT_HOSTS = ("https://www.mturk.com", "https://workersandbox.mturk.com")
Platform = Literal["prolific", "mturk", "open"]
_REDIRECT_FIELDS = ("prolific_redirect_url", "mturk_redirect_url", "open_redirect_url")
ENDING_NAMES = ("failed_checks", "excluded", "declined_consent", "screened_out")
# `pinned`: the codes are the config's; `generated`: the server makes one random code per
# ending and keeps it in the data dir (app/server/flow/completion_codes.py)
CodeSource = Literal["pinned", "generated"]


class RecruitmentConfig(StrictModel):
    """The `recruitment` section: where participants come from, what the server demands of
    them (enforced by recruitment.py), and where they go.

    `platform` is enforced at session start: `prolific` needs PROLIFIC_PID (24 hex),
    STUDY_ID (equal to `prolific_study_id` when that is set) and SESSION_ID; `mturk`
    needs workerId, assignmentId and hitId; `open` takes anonymous visitors (lab
    studies). Lab members use the researcher preview link instead; those sessions are
    marked pilot and never count.

    `closed` and `max_counted_sessions` stop new participants (they see a page that asks
    them to return the study); sessions already started go on, and lab previews still open.

    `codes: generated` leaves every completion code out of the config (which is public in a
    repository): the server makes one random code per ending on first use and keeps it in
    the data dir; `pinned` (the default) uses the codes written here.
    """

    # `prolific`, `mturk` or `open` (anonymous lab visitors): which URL parameters a session must
    # start with
    platform: Platform = "prolific"
    # `pinned`: the completion codes written here; `generated`: the server makes one random code per
    # ending and keeps it in the data dir (leave every code out)
    codes: CodeSource = "pinned"
    closed: bool = False  # true: new participants are turned away (the study is closed)
    # the study is full once this many sessions count (in progress or completed validly)
    max_counted_sessions: int | None = Field(default=None, ge=1)
    # Prolific's study id (up to 24 hex digits); when set, a session whose STUDY_ID differs is
    # refused; '' = not checked
    prolific_study_id: str = Field(default="", pattern=r"^[0-9a-fA-F]{0,24}$")
    # the code a validly completed session gets (letters, digits, _ and -, at most 64); required
    # with `codes: pinned`
    completion_code: str = Field(default="", max_length=64, pattern=r"^[A-Za-z0-9_-]*$")
    # where a Prolific participant is sent at the end; https:// only, {completion_code} is the one
    # placeholder
    prolific_redirect_url: str = "https://app.prolific.com/submissions/complete?cc={completion_code}"
    # where an MTurk worker is sent at the end ('' = no redirect: the page shows the code); https://
    # only, {completion_code} the one placeholder
    mturk_redirect_url: str = ""
    # where an `open` (lab) participant is sent at the end ('' = none: the page shows the code);
    # https:// only, {completion_code} the one placeholder
    open_redirect_url: str = ""
    # where an MTurk completion may post its form (turkSubmitTo must be one of these)
    mturk_submit_hosts: list[str] = list(MTURK_SUBMIT_HOSTS)
    # the codes and messages of the endings other than a valid completion
    endings: Endings = Endings()
    hourly_pay: HourlyPay | None = None  # None: the pay is stated on the platform only

    # a recruitment without a pay rate, or that pins its codes, dumps as before the keys
    # existed (same config hash); one serializer, as a model has one
    _without_new_keys = omitted_when(empty=("hourly_pay",), default=("codes",))

    @model_validator(mode="after")
    def _codes_from_one_source(self) -> "RecruitmentConfig":
        pinned = self.pinned_codes()
        if self.codes == "pinned" and not self.completion_code:
            raise ValueError("completion_code: required (or `codes: generated`: the server "
                             "makes every ending's code)")
        if self.codes == "generated" and pinned:
            raise ValueError(f"{next(iter(pinned))}: leave it out: with `codes: generated` "
                             "the server makes every ending's code (`tomstudy codes`)")
        return self

    @model_validator(mode="after")
    def _redirects_render(self) -> "RecruitmentConfig":
        for name in _REDIRECT_FIELDS:
            check_redirect_template(name, getattr(self, name), self.completion_code)
        for host in self.mturk_submit_hosts:
            if not host.startswith(("https://", "http://127.0.0.1:")) or host.count("/") != 2:
                raise ValueError("mturk_submit_hosts: each must be an origin such as "
                                 f"https://www.mturk.com (http only on 127.0.0.1), got {host!r}")
        return self

    def pinned_codes(self) -> dict[str, str]:
        """Every code written in this section, by its field path (recruitment.…)."""
        found = {"recruitment.completion_code": self.completion_code}
        for name in ENDING_NAMES:
            found[f"recruitment.endings.{name}.completion_code"] = getattr(
                self.endings, name).completion_code
        return {path: code for path, code in found.items() if code}

    def with_codes(self, codes: dict[str, str]) -> "RecruitmentConfig":
        """This section with `codes` (outcome -> code) as its codes (generated ones)."""
        endings = self.endings.model_copy(update={
            name: getattr(self.endings, name).model_copy(update={"completion_code": codes[name]})
            for name in ENDING_NAMES})
        return self.model_copy(update={"completion_code": codes["completed"],
                                       "endings": endings})

    def ending(self, outcome: str) -> Ending:
        """The code and message of `outcome` (one of app/server/flow/endings.py's OUTCOMES)."""
        if outcome == "completed":
            return Ending(completion_code=self.completion_code)
        chosen = getattr(self.endings, outcome)
        fallback = {"failed_checks": "completed", "excluded": "failed_checks"}.get(outcome)
        if fallback and not chosen.completion_code:
            code = self.ending(fallback).completion_code
            return chosen.model_copy(update={"completion_code": code})
        return chosen


def check_redirect_template(name: str, template: str, completion_code: str) -> str:
    """The template rendered with the code; ValueError naming `name` unless it is '' or https."""
    try:
        url = template.format(completion_code=completion_code)
    except (KeyError, IndexError, ValueError) as err:
        raise ValueError(f"{name}: only the placeholder {{completion_code}} is allowed "
                         f"({type(err).__name__}: {err})") from None
    if url and not url.startswith("https://"):
        raise ValueError(f"{name}: must be empty or an https:// URL, got {url[:60]!r}")
    return url


class PredictionInput(StrictModel):
    """Limits on a clicked move, as fractions of the robot's largest step in the bank data.

    The reach circle is the robot's 99.5th-percentile step times `max_step_factor`: a small
    margin over what the robot really does, so a click near its edge is not refused for a
    pixel and the circle does not invite moves several times the robot's step.
    """

    # the reach circle's radius as a multiple (> 0) of the robot's 99.5th-percentile step in the
    # bank data; a click beyond it is refused
    max_step_factor: float = Field(default=1.1, gt=0)
    # the shortest move accepted, as a fraction (0-1) of the reach radius; a shorter click is
    # refused (the bank's min_step_m)
    min_step_fraction: float = Field(default=0.1, gt=0, lt=1)


class ModelFamily(StrictModel):
    """Which training seeds of Ours and the VAE a study's bank answers with, per world.

    Every seed is trained (in `tomstudy bundle build`, never at serve time) and every seed's
    answers are stored in the bank, so results can be reported per seed and for the family.
    `seeds[0]` is the primary seed: its answers fill the live export's ours_*/vae_* columns and
    the dashboard. Seed k's VAE takes its k-means k from seed k's Ours. Checkpoints live at
    app.layout's `checkpoint(world, model, seed)`.
    """

    # training seeds (distinct, >= 0, 1-32 of them) of Ours and the VAE; seeds[0] is the primary;
    # each seed is trained in `tomstudy bundle build`, so changing them rebuilds the bank
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1, max_length=32)

    @model_validator(mode="after")
    def _distinct(self) -> "ModelFamily":
        if len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise ValueError("seeds: must be distinct integers >= 0")
        return self

    @property
    def primary(self) -> int:
        """The seed whose answers the live export and the dashboard show."""
        return self.seeds[0]


class MainTrialSelection(StrictModel):
    """Which held-out segments become main trials (app/bank/build.py), in two arms.

    `random`: every main trial is in the random arm: the first usable segments, robot labels
    taking turns. `models_disagree`: the first `random_arm_trials` usable segments form the
    random arm as above; for the rest (the `models_disagree` arm), build `candidates_per_trial`
    times as many further usable segments and keep, per robot label, those where the two model
    families disagree most: the mean 1-cos between every Ours seed's and every VAE seed's answers
    over the start states and steps. Where the models agree no prediction can favour either
    (controversial stimuli: Golan, Raju & Kriegeskorte 2020, PNAS 117:29330-29337). The rule
    reads the models' answers only, averaged over seeds so no single training run decides, never
    a participant's or a simulated observer's, and favours neither model. Each participant sees
    both arms in proportion to their sizes (app/assignment.py `pick_by_arm`).
    `discriminability` (issue 30): the second arm keeps, per robot label, the candidates where
    the hypotheses differ most: the smallest, over the coarse observers of the family
    (app/observers/family.py), of the precise observer's expected family err_ours - err_vae
    minus that coarse observer's, scored on the `selection_seeds` only, so the seeds left out
    confirm the design (`tomstudy instrument`). It reads the observers' expected answers and
    the models' answers of the selection seeds, never a participant's.
    """

    # `random`: every main trial in the random arm; `models_disagree` or `discriminability`: a
    # second arm chosen by that rule (see above); changing it rebuilds the bank
    rule: Literal["random", "models_disagree", "discriminability"] = "random"
    # candidate segments built per second-arm trial (1-8; 1 with rule random); more candidates let
    # the rule pick more extreme ones
    candidates_per_trial: int = Field(default=1, ge=1, le=8)
    # with a second-arm rule: how many of bank_trials_per_world stay in the random arm
    # (0..bank_trials_per_world)
    random_arm_trials: int = Field(default=0, ge=0)
    # with rule discriminability only: the model seeds the rule reads (some, not all, of
    # models.seeds); the others confirm the design
    selection_seeds: list[int] = Field(default_factory=list)

    # a selection without selection seeds dumps as before the key existed (same config hash)
    _without_empty_seeds = omitted_when_empty("selection_seeds")

    @model_validator(mode="after")
    def _one_candidate_when_random(self) -> "MainTrialSelection":
        if self.rule == "random" and self.candidates_per_trial != 1:
            raise ValueError("candidates_per_trial: must be 1 with rule random "
                             "(it would only move the attention checks to other segments)")
        if self.rule == "random" and self.random_arm_trials:
            raise ValueError("random_arm_trials: only with rule models_disagree (with rule "
                             "random every main trial is in the random arm)")
        if (self.rule == "discriminability") != bool(self.selection_seeds):
            raise ValueError("selection_seeds: required with rule discriminability (the seeds "
                             "the design may read), and only with it")
        return self

    @property
    def second_arm(self) -> str | None:
        """The name of the arm chosen by the rule (None when every trial is random)."""
        return None if self.rule == "random" else self.rule

    def arm_sizes(self, bank_trials: int) -> dict[str, int]:
        """Main trials per arm in a world's bank of `bank_trials` main trials."""
        if self.rule == "random":
            return {"random": bank_trials}
        return {"random": self.random_arm_trials,
                self.rule: bank_trials - self.random_arm_trials}


# a marked placeholder a lab must replace before going live, e.g. "[YOUR INSTITUTION]"
PLACEHOLDER = r"\[[A-Z][A-Z0-9 ,.'/&()-]*\]"
_EMAIL_OR_PLACEHOLDER = rf"^({PLACEHOLDER}|[^@\s]+@[^@\s]+\.[^@\s]+)$"


class Investigator(StrictModel):
    """A researcher the participant can contact."""

    # the researcher's name (1-120 characters)
    name: str = Field(min_length=1, max_length=120)
    role: str = Field(default="", max_length=120)  # e.g. "principal investigator"
    # their contact address (an email, or a [PLACEHOLDER] that production refuses)
    email: str = Field(pattern=_EMAIL_OR_PLACEHOLDER, max_length=200)


class ConsentForm(StrictModel):
    """The consent page's typed sections (app/study/consent.py renders them, with the time and
    pay from the estimate). Production refuses a form that still holds a [PLACEHOLDER]."""

    # the institution running the study, as the consent page names it
    institution: str = Field(min_length=1)
    # the researchers a participant can contact (at least one)
    investigators: list[Investigator] = Field(min_length=1)
    ethics_approval: str = Field(min_length=1)  # the review board and its approval id
    purpose: str = Field(min_length=1)  # what the study is about and what the participant does
    recorded: str = Field(min_length=1)  # what is recorded, and what is not
    retention: str = Field(min_length=1)  # how long data are kept, where, and who they go to
    # that taking part is voluntary, in the study's own words
    voluntary: str = Field(min_length=1)
    withdrawal: str = Field(min_length=1)  # how to stop, and to have one's data removed
    # the risks and discomforts of taking part (or that there are none beyond everyday use of a
    # computer)
    risks: str = Field(min_length=1)


class WorldIntro(StrictModel):
    """The screen before a world's practice: its name for participants and what is in it."""

    # the world's name as participants see it on its opening screen (1-80 characters)
    title: str = Field(min_length=1, max_length=80)
    # what is in the world and what its parts mean (goals, obstacles, lanes)
    text: str = Field(min_length=1)


class StudyConfig(StrictModel):
    """Everything that defines one online study."""

    # the study's name on every page, the consent and instructions headings, and the MTurk preview
    title: str
    # what the MTurk HIT preview shows (default: the title only); {duration} and {pay} are
    # rendered from the estimate (app/study/estimate.py), so no time is typed by hand
    description: str = ""
    consent: ConsentForm | None = None  # the consent page's typed sections
    consent_text: str = ""  # before the typed form: free text, shown only without `consent`
    # the instructions page's text, shown after consent and before the first world
    instructions_text: str
    # per world: the screen that opens its part (what goals, obstacles or lanes mean)
    world_intros: dict[WorldName, WorldIntro]
    # what every page calls the two agents (app/study/words.py): the study's, as its
    # instructions page is shared by its worlds; default the paper study's robot and person
    words: ParticipantWords = ParticipantWords()
    demo: DemoName = DEFAULT_DEMO  # the instructions' illustration: `obstacle` or `road`
    # the worlds each participant sees (each once): a simulated world or a recorded one with
    # study_configs/worlds/<name>.yaml; changing it rebuilds the bank
    worlds: list[WorldName] = Field(min_length=1)
    # true: every order of `worlds` is used, each new participant getting the least-used one; false:
    # every participant sees them in the order listed
    counterbalance_world_order: bool = True
    # scored main trials per world in each participant's plan (>= 1, at most bank_trials_per_world),
    # the least-exposed ones of the bank
    trials_per_world: int = Field(ge=1)
    # complete example interactions shown before each trial's segment (>= 0); changing it rebuilds
    # the bank
    examples_per_trial: int = Field(ge=0)
    # the range of steps of the partial interaction a trial shows
    segment_steps: SegmentSteps
    start_states: int = Field(ge=1)  # per trial: own + data-covered (bank/start_states.py)
    # moves the participant clicks per start state (>= 1), one per step of the world; changing it
    # rebuilds the bank
    steps_to_predict: int = Field(ge=1)
    practice_trials: int = Field(default=1, ge=0)  # per world, before its scored trials
    # main trials the bank holds per world (>= trials_per_world); participants draw from them, so
    # more trials spread the exposures
    bank_trials_per_world: int = Field(ge=1)
    # seed (>= 0) of the bank's random draws (segments, their lengths, examples, start states),
    # mixed with the world's index; a new seed gives a different bank
    bank_seed: int = Field(default=0, ge=0)
    # which held-out segments become main trials, and in which arm
    main_trial_selection: MainTrialSelection = MainTrialSelection()
    # the attention check trials and the rule that makes them fair
    attention_checks: AttentionChecks = AttentionChecks()
    # how long a clicked move may be, relative to the robot's own steps
    prediction_input: PredictionInput = PredictionInput()
    # the closing questions, in order (keys unique); [] = none
    survey: list[SurveyQuestion] = []
    # where participants come from, what a session must start with, and where they go at the end
    recruitment: RecruitmentConfig
    # the planned number of participants (>= 1): the preregistration's N, the dashboard's progress
    # and the base of the live-session cap
    target_sample_size: int = Field(ge=1)
    # the rules that exclude a participant or drop a trial in the analysis and the endings
    exclusions: ExclusionRules = ExclusionRules()
    # minutes (> 0) without an update after which an unfinished session is stale: it stops counting
    # toward the balance and the places (a stale session that completes validly counts again)
    in_progress_timeout_min: float = Field(default=90.0, gt=0)
    # a session that has not consented this long after its start holds nothing: its external
    # id may start again (it never counted: a session counts from consent on, places.py)
    consent_timeout_min: float = Field(default=10.0, gt=0)
    # at most this x target_sample_size unfinished sessions run at once (pilots aside): a
    # bound on what anonymous traffic can make the server hold (sessions.py)
    max_live_sessions_per_target: float = Field(default=10.0, ge=1)
    # which training seeds of Ours and the VAE the bank answers with
    models: ModelFamily = ModelFamily()
    # plug-in predictors (app/predictors/registry.py) whose answers the bank stores beside
    # Ours', the VAE's and constant velocity's: installed entry point names, never code
    predictors: list[str] = []
    # `built`: the bundle is made in the data dir by `tomstudy bundle build`; `shipped`: the bundle
    # in study_configs/bundles/ (in git) is served as it is
    bundle: BundleSource = "built"
    # worlds whose design cannot meet the design goal (`tomstudy instrument`): world -> what it
    # can and cannot test; reported as exploratory, never as a test of the hypothesis
    exploratory_worlds: dict[str, Annotated[str, Field(min_length=20)]] = {}
    # the equivalence test beside the primary one (analysis/equivalence.py): an Ours - VAE
    # difference in mean alignment error smaller than this is treated as no difference
    smallest_effect_of_interest: float = Field(default=SMALLEST_EFFECT_OF_INTEREST, gt=0, le=2)

    @field_validator("predictors")
    @classmethod
    def _registered(cls, names: list[str]) -> list[str]:
        return check_names(names)

    # a study without plug-ins (or exploratory worlds, or with the default smallest effect,
    # words or demo) dumps as before the keys existed: same config hash, so sessions that ran
    # it before an upgrade still show as running the loaded config
    _without_new_keys = omitted_when(empty=("predictors", "exploratory_worlds", "consent"),
                                     default=("smallest_effect_of_interest",
                                              "consent_timeout_min", "words", "demo"))

    @model_validator(mode="after")
    def _consistent(self) -> "StudyConfig":
        if self.consent is None and not self.consent_text.strip():
            raise ValueError("consent: the consent form's sections are required")
        unexplained = [w for w in self.worlds if w not in self.world_intros]
        if unexplained:
            raise ValueError(f"world_intros: no introduction for world(s) {', '.join(unexplained)}")
        strangers = sorted(set(self.exploratory_worlds) - set(self.worlds))
        if strangers:
            raise ValueError(f"exploratory_worlds: {', '.join(strangers)} not in worlds")
        if len(set(self.worlds)) != len(self.worlds):
            raise ValueError("worlds: each world may appear once")
        if self.bank_trials_per_world < self.trials_per_world:
            raise ValueError("bank_trials_per_world must be >= trials_per_world")
        if self.main_trial_selection.random_arm_trials > self.bank_trials_per_world:
            raise ValueError("main_trial_selection.random_arm_trials must be <= "
                             "bank_trials_per_world")
        chosen_on = self.main_trial_selection.selection_seeds
        if chosen_on and not (set(chosen_on) < set(self.models.seeds)):
            raise ValueError("main_trial_selection.selection_seeds: must be some, not all, of "
                             "models.seeds (the others confirm the design)")
        if self.attention_checks.min_passing_starts > self.start_states:
            raise ValueError("attention_checks.min_passing_starts must be <= start_states")
        keys = [q.key for q in self.survey]
        if len(set(keys)) != len(keys):
            raise ValueError("survey: question keys must be unique")
        return self


def stored_predictors(config: StudyConfig) -> list[str]:
    """The code predictors a study's bank answers with, as the export names them: the coarse
    observers, then the config's plug-ins."""
    return [*COARSE_OBSERVERS, *config.predictors]


def held_out_seeds(config: StudyConfig) -> list[int]:
    """The model seeds no design choice read: all but the selection seeds (none for a rule that
    reads every seed's family)."""
    chosen_on = config.main_trial_selection.selection_seeds
    return [s for s in config.models.seeds if s not in chosen_on] if chosen_on else []


# the study config's keys that shape the trial bank: a change to any of them rebuilds it
BANK_DESIGN_KEYS = ("worlds", "examples_per_trial", "segment_steps", "start_states",
                    "steps_to_predict", "practice_trials", "bank_trials_per_world", "bank_seed",
                    "main_trial_selection", "prediction_input", "models", "predictors")
# the attention check rule's keys that shape the bank (which segment is a fair check): the rest
# of `attention_checks` is retired
BANK_ATTENTION_KEYS = ("per_world", "max_angle_deg", "min_passing_starts",
                       "min_attentive_pass_rate")


def bank_design(config: dict) -> dict | None:
    """The bank-shaping part of a study config (validated, so defaults count), or None if the
    config no longer validates."""
    try:
        model = StudyConfig.model_validate(config)
    except ValidationError:
        return None
    valid = model.model_dump(mode="json")
    design = {key: valid.get(key, []) for key in BANK_DESIGN_KEYS}  # only predictors may lack
    # read from the model: a key at its default is left out of the dump
    return design | {"attention_checks": {k: getattr(model.attention_checks, k)
                                          for k in BANK_ATTENTION_KEYS}}


def live_session_cap(config: StudyConfig) -> int:
    """How many unfinished counted sessions the study runs at once."""
    return math.ceil(config.max_live_sessions_per_target * config.target_sample_size)


def config_sha256(config: StudyConfig) -> str:
    """SHA-256 of the validated config as canonical JSON: comments and key order do not count."""
    return json_sha256(config.model_dump(mode="json"))


def study_config_path(settings: Settings, study_id: str) -> Path:
    """study_configs/<study_id>.yaml under the configured configs dir."""
    if not study_id.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"study: invalid study id {study_id!r}")
    return Path(settings.configs_dir) / f"{study_id}.yaml"


def load_study_config(settings: Settings, study_id: str) -> StudyConfig:
    """Read and validate a study config; a bad key raises ConfigError naming it, as does a
    world without its study_configs/worlds/<world>.yaml."""
    path = study_config_path(settings, study_id)
    config = _load(path)
    for index, world in enumerate(config.worlds):
        world_file = Path(settings.configs_dir) / "worlds" / f"{world}.yaml"
        if not world_file.is_file():
            raise ConfigError(f"{path}: worlds.{index}: no world {world!r}: describe it in "
                              f"{world_file} (a recorded world: kind: recorded)")
    return config


@lru_cache(maxsize=16)
def _load(path: Path) -> StudyConfig:
    return load_yaml_model(path, StudyConfig)
