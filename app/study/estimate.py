"""How long a study takes a participant, from its bank and texts, and what that time pays.

Clip time is what the page really plays: every example and the segment at the player's step
time, with its pause between clips (read from frontend/static/js/player.js, not restated
here). Reading time is every text the participant reads at a stated words per minute; every
press and click (a predicted position, a Next, a Continue) takes a stated pace. Watching
clips again is not counted: it is the participant's choice.
"""

import math
import re
from dataclasses import dataclass
from pathlib import Path

from app.settings import REPO_ROOT
from app.study.config import StudyConfig
from app.study.consent import Advert, consent_words, money, render
from app.study.trials import TrialBank
from app.study.words import participant_texts

PLAYER_JS = REPO_ROOT / "frontend" / "static" / "js" / "player.js"
# what the trial screen asks before the prediction prompt, read once per part (trial.js `watch`);
# the prompts that name an agent are the study's own (app/study/words.py participant_texts)
WATCH_PROMPTS = ("Watch the clips closely. Press the button to make your predictions, or watch "
                 "the clips again.")
# presses outside the trials: consent's box and Continue, instructions' Continue
FLOW_PRESSES = 3
PART_PRESSES = 2  # per part: "Start the practice", "Start trial 1"
ADVERTISED_ROUNDING_MIN = 1  # advertised time = the median estimate rounded up to whole minutes


@dataclass(frozen=True)
class Pace:
    """How fast a participant reads, clicks and types."""

    words_per_minute: float = 230.0
    seconds_per_click: float = 2.5
    seconds_per_text_answer: float = 30.0  # a free-text survey answer of a sentence or two

    def describe(self) -> str:
        """The pace in words, as the output states it."""
        return (f"{self.words_per_minute:g} words/min, {self.seconds_per_click:g} s per click, "
                f"{self.seconds_per_text_answer:g} s per written answer")


MEDIAN_PACE = Pace()
SLOW_PACE = Pace(words_per_minute=180.0, seconds_per_click=4.0, seconds_per_text_answer=60.0)


@dataclass(frozen=True)
class PlayerTiming:
    """The participant page's clip timing (frontend/static/js/player.js)."""

    step_s: float
    pause_between_clips_s: float


def player_timing(path: Path = PLAYER_JS) -> PlayerTiming:
    """STEP_SECONDS and PAUSE_BETWEEN_CLIPS_MS as the page plays them."""
    source = path.read_text()
    step = re.search(r"export const STEP_SECONDS = ([0-9.]+);", source)
    pause = re.search(r"const PAUSE_BETWEEN_CLIPS_MS = ([0-9.]+);", source)
    if not step or not pause:
        raise ValueError(f"{path}: STEP_SECONDS or PAUSE_BETWEEN_CLIPS_MS not found")
    return PlayerTiming(float(step.group(1)), float(pause.group(1)) / 1000)


@dataclass(frozen=True)
class Workload:
    """What one participant does, independent of pace."""

    clip_s: float  # seconds of animation and pauses, every trial's clips played once
    words: int  # words read
    clicks: int  # clicks and presses
    text_answers: int  # free-text survey answers
    trials: int  # practice, main and attention trials


@dataclass(frozen=True)
class Estimate:
    """One participant's expected minutes at one pace, by part."""

    pace: Pace
    clips_min: float
    reading_min: float
    clicking_min: float
    writing_min: float

    @property
    def total_min(self) -> float:
        """The whole session in minutes."""
        return self.clips_min + self.reading_min + self.clicking_min + self.writing_min


def words(text: str) -> int:
    """Words in `text` as a reader counts them."""
    return len(text.split())


def clip_seconds(steps: int, timing: PlayerTiming) -> float:
    """One clip of `steps` steps on the page, with the pause after it."""
    return steps * timing.step_s + timing.pause_between_clips_s


def trial_clip_seconds(trial, timing: PlayerTiming) -> float:
    """A trial's examples and segment played once."""
    clips = [*trial.examples, trial.segment]
    return sum(clip_seconds(len(c.positions) - 1, timing) for c in clips)


def mean_clip_seconds(bank: TrialBank, world: str, kind: str, timing: PlayerTiming) -> float:
    """The mean clip time of a world's trials of one kind (the main trials' for a kind the
    bank lacks: a participant sees a random draw of them)."""
    trials = bank.trials_of(world, kind) or bank.trials_of(world, "main")
    return sum(trial_clip_seconds(t, timing) for t in trials) / len(trials)


def texts_read(config: StudyConfig, advert_words: int) -> int:
    """Every word the participant reads outside the clips (`advert_words`: the description's
    and the consent page's, which state the time)."""
    intros = sum(words(i.title) + words(i.text) for w, i in config.world_intros.items()
                 if w in config.worlds)
    survey = sum(words(q.text) + sum(words(o) for o in q.options) for q in config.survey)
    texts = participant_texts(config.words)
    prompts = len(config.worlds) * (words(WATCH_PROMPTS) + words(texts["predict_prompt"])
                                    + config.practice_trials * words(texts["practice_feedback"]))
    ending = words(config.recruitment.ending("completed").message)
    return (advert_words + words(config.instructions_text) + intros + survey + prompts + ending)


def workload(config: StudyConfig, bank: TrialBank, advert_words: int,
             timing: PlayerTiming | None = None) -> Workload:
    """What the study asks of one participant: clips, words, clicks, written answers."""
    timing = timing or player_timing()
    per_kind = {"practice": config.practice_trials, "main": config.trials_per_world,
                "attention": config.attention_checks.per_world}
    clip_s = sum(n * mean_clip_seconds(bank, world, kind, timing)
                 for world in config.worlds for kind, n in per_kind.items() if n)
    trials = len(config.worlds) * sum(per_kind.values())
    # per trial: "Make predictions", per start state each position and its Next, the break
    per_trial = 1 + config.start_states * (config.steps_to_predict + 1) + 1
    # a practice trial's feedback: one press per start position (Next ..., then Continue)
    feedback = len(config.worlds) * config.practice_trials * config.start_states
    survey_clicks = sum(q.kind != "text" for q in config.survey) + 1  # answers and Finish
    clicks = (FLOW_PRESSES + PART_PRESSES * len(config.worlds) + trials * per_trial + feedback
              + survey_clicks)
    text_answers = sum(q.kind == "text" for q in config.survey)
    return Workload(clip_s, texts_read(config, advert_words), clicks, text_answers, trials)


def estimate(work: Workload, pace: Pace) -> Estimate:
    """`work` at `pace`, in minutes."""
    return Estimate(pace, clips_min=work.clip_s / 60,
                    reading_min=work.words / pace.words_per_minute,
                    clicking_min=work.clicks * pace.seconds_per_click / 60,
                    writing_min=work.text_answers * pace.seconds_per_text_answer / 60)


def advertised_minutes(median_min: float) -> int:
    """The time a study states: the median participant's, rounded up to whole minutes."""
    step = ADVERTISED_ROUNDING_MIN
    return int(math.ceil(median_min / step - 1e-9) * step)


def pay_for(minutes: float, hourly: float) -> float:
    """The pay for `minutes` at `hourly`, rounded up to a whole cent."""
    return math.ceil(round(minutes / 60 * hourly * 100, 6)) / 100


@dataclass(frozen=True)
class StudyEstimate:
    """A study's time at the median and the slow pace, and what it states."""

    work: Workload
    median: Estimate
    slow: Estimate
    advert: Advert


def advert_for(config: StudyConfig, minutes: int) -> Advert:
    """The stated time, with the pay at the study's hourly rate (if it sets one)."""
    rate = config.recruitment.hourly_pay
    if rate is None:
        return Advert(minutes, "", "")
    pay = pay_for(minutes, rate.amount)
    return Advert(minutes, money(pay, rate.currency), f"{money(rate.amount, rate.currency)} per "
                  "hour", pay, rate.currency)


def study_estimate(config: StudyConfig, bank: TrialBank, timing: PlayerTiming | None = None,
                   median_pace: Pace = MEDIAN_PACE, slow_pace: Pace = SLOW_PACE) -> StudyEstimate:
    """The study's expected time from its bank and texts, and the time and pay it states."""
    # the consent page's words do not depend on the figures it states (same word count)
    provisional = advert_for(config, 0)
    advert_words = (consent_words(config, provisional)
                    + words(render(config.description, provisional)))
    work = workload(config, bank, advert_words, timing)
    median = estimate(work, median_pace)
    return StudyEstimate(work, median, estimate(work, slow_pace),
                         advert_for(config, advertised_minutes(median.total_min)))


def estimate_lines(study_id: str, found: StudyEstimate, timing: PlayerTiming) -> list[str]:
    """What `tomstudy estimate` prints."""
    w, advert = found.work, found.advert
    lines = [f"study {study_id}: {w.trials} trials, clips played once: "
             f"{w.clip_s / 60:.1f} min (step {timing.step_s:g} s, "
             f"{timing.pause_between_clips_s:g} s between clips: frontend player.js); "
             f"{w.words} words read, {w.clicks} clicks, {w.text_answers} written answer(s)"]
    for name, e in (("median participant", found.median), ("slow participant", found.slow)):
        lines.append(f"{name} ({e.pace.describe()}): {e.total_min:.1f} min = clips "
                     f"{e.clips_min:.1f} + reading {e.reading_min:.1f} + clicking "
                     f"{e.clicking_min:.1f} + writing {e.writing_min:.1f}")
    lines.append(f"advertised: {advert.minutes} min (the median participant's, rounded up to "
                 f"whole minutes); rendered as {{duration}} in the description and consent")
    if advert.pay:
        slow_rate = advert.pay_amount / (found.slow.total_min / 60)
        lines.append(f"pay: {advert.pay} at {advert.hourly}; a slow participant earns "
                     f"{money(slow_rate, advert.currency)} per hour")
    else:
        lines.append("pay: recruitment.hourly_pay is not set (no pay stated)")
    return lines
