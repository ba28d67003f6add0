"""Observers in a recorded world: the intents are turning one way, straight on or the other,
at the rate the example clips' cars turn."""

import numpy as np
import pytest

from app.observers import inverse_planning
from app.observers.config import default_observers
from app.settings import REPO_ROOT
from app.study.clicks import check_points
from app.study.trials import WorldBank
from app.worlds.intents import TURN_SIGNS, TurnIntents, heading_changes, turn_rate

CONFIG = default_observers(REPO_ROOT / "study_configs")
DT = 0.4
SCENE = {"world": "roundabout", "dt_s": DT, "frame": "recorded", "frame_speed_mps": 0.0,
         "bounds": {"x_min_m": -60.0, "x_max_m": 60.0, "y_min_m": -60.0, "y_max_m": 60.0},
         "lanes": [], "obstacles": [], "goals": [], "agents": [],
         "recorded": {"source": "test", "lines": [], "driven": None, "view_span_m": 60.0}}


def arc(rate_deg_s: float, steps: int, speed: float = 8.0, heading: float = 0.0) -> np.ndarray:
    """A track [steps+1, 2] at `speed` whose heading changes by `rate_deg_s`."""
    headings = heading + np.radians(rate_deg_s) * DT * np.arange(steps)
    moves = speed * DT * np.stack([np.cos(headings), np.sin(headings)], axis=1)
    return np.concatenate([np.zeros((1, 2)), np.cumsum(moves, axis=0)])


def payload(segment: np.ndarray, examples: list[np.ndarray]) -> dict:
    def clip(track):
        human = np.full_like(track, 40.0)
        return {"positions": np.stack([track, human], axis=1).tolist()}

    end = segment[-1]
    return {"scene": SCENE, "dt_s": DT, "segment": clip(segment),
            "examples": [clip(e) for e in examples],
            "start_states": [{"robot": (end + [0.0, dy]).tolist(), "human": [40.0, 40.0],
                              "robot_heading": 0.0, "human_heading": 0.0} for dy in (0, 6)],
            "steps_to_predict": 3, "min_step_m": 0.3, "max_step_m": 6.0, "trial_id": "t"}


EXAMPLES = [arc(20, 10), arc(-20, 10), arc(0, 10), arc(22, 10)]


def test_the_nominal_turn_rate_is_the_examples_median_turning_rate():
    assert np.degrees(turn_rate(EXAMPLES, DT)) == pytest.approx(20.0, abs=0.5)
    assert np.degrees(turn_rate([arc(0, 10)], DT)) == pytest.approx(5.0)  # the floor


@pytest.mark.parametrize("rate, sign", [(20, 1), (0, 0), (-20, -1)])
def test_the_posterior_reads_the_way_the_segment_turns(rate, sign):
    reading = inverse_planning.infer_intent(payload(arc(rate, 6), EXAMPLES), CONFIG)
    assert reading.intents.tolist() == TURN_SIGNS.tolist()
    assert reading.intents[int(np.argmax(reading.posterior))] == sign
    assert reading.posterior.max() > 0.8


def test_example_outcomes_are_the_way_each_clip_turned():
    intents = TurnIntents(DT, arc(0, 6), EXAMPLES)
    assert [int(TURN_SIGNS[intents.outcome(e)]) for e in EXAMPLES] == [1, -1, 0, 1]


def test_the_coarse_move_keeps_turning_at_the_intents_rate_and_the_segments_speed():
    segment = arc(20, 6)
    intents = TurnIntents(DT, segment, EXAMPLES)
    move = intents.course(1, np.zeros((1, 2)), 1.0)
    last = np.arctan2(*np.diff(segment, axis=0)[-1][::-1])
    track = [segment[-1]]
    for _ in range(3):
        direction, length = move(0, track[-1])
        assert length == pytest.approx(8.0 * DT, rel=1e-6)
        track.append(track[-1] + length * direction)
    turns = np.degrees(heading_changes(np.array([segment[-2], *track])))
    assert turns == pytest.approx([20 * DT] * 3, abs=0.3)
    assert np.degrees(np.arctan2(*direction[::-1]) - last) == pytest.approx(60 * DT, abs=0.5)


def test_the_coarse_move_turns_from_the_heading_drawn_at_each_start():
    """A relocated recorded start is drawn as the recorded car stood there: the coarse
    observer turns from that heading, not from the segment's last move."""
    intents = TurnIntents(DT, arc(0, 6), EXAMPLES)
    drawn = [0.0, np.radians(90)]
    move = intents.course(0, np.zeros((2, 2)), 1.0, drawn)
    for i, heading in enumerate(drawn):
        direction, _ = move(i, np.zeros(2))
        assert np.arctan2(*direction[::-1]) == pytest.approx(heading, abs=1e-9)


@pytest.mark.parametrize("preset", ["coarse", "precise", "random"])
def test_every_preset_clicks_what_the_server_accepts(preset):
    p = payload(arc(20, 6), EXAMPLES)
    policy = np.full((2, 3, 2), [8.0, 0.0])
    clicks = inverse_planning.predict(preset, p, np.random.default_rng(1), policy, CONFIG)
    world = WorldBank(world="roundabout", dt_s=DT, scene=SCENE, robot_label_name="robot_turn",
                      label_names=["left", "straight", "right"], max_step_m=6.0,
                      min_step_m=0.3, trials=[])
    starts = np.array([s["robot"] for s in p["start_states"]])
    check_points(world, starts, clicks)  # raises Refused on a click the server refuses
