"""Simulated observers: inverse planning reads intents, clicks stay valid, noise matches the
config, no model output is ever read; power and the instrument check run."""

import copy
import json

import numpy as np
import pytest
import yaml

from analysis.metrics import participant_means
from app.configio import ConfigError
from app.observers import inverse_planning
from app.observers.config import load_observers
from app.observers.simulated_study import (
    instrument_check,
    population_frames,
    power_curve,
    run_instrument,
    separation,
    simulate_participants,
    simulated_payload,
    trial_contrast,
)
from app.settings import REPO_ROOT
from app.worlds.intents import forward_speed
from tests.analysis.fixed_data import (
    HIGHWAY_SCENE,
    OBSTACLE_SCENE,
    highway_segment,
    obstacle_segment,
    payload,
    trial_bank,
)
from tests.observers.observer_inputs import (
    CONFIG,
    GOALS,
    MAP,
    QUIET,
    bank_with_examples,
    goal_clip,
    lane_clip,
)


def _assert_valid(p: dict, clicks: np.ndarray) -> None:
    b = p["scene"]["bounds"]
    assert clicks.shape == (len(p["start_states"]), p["steps_to_predict"], 2)
    assert np.all((clicks[..., 0] > b["x_min_m"]) & (clicks[..., 0] < b["x_max_m"]))
    assert np.all((clicks[..., 1] > b["y_min_m"]) & (clicks[..., 1] < b["y_max_m"]))
    starts = inverse_planning.start_positions(p)[:, None, :]
    steps = np.linalg.norm(np.diff(np.concatenate([starts, clicks], axis=1), axis=1), axis=-1)
    assert np.all(steps >= p["min_step_m"]) and np.all(steps <= p["max_step_m"])


def merged_segment(lane_from: int, lane_to: int) -> list:
    """The robot completes a lane change in 4 steps, then holds the new lane for 3."""
    ys = np.concatenate([np.linspace(4.0 * lane_from, 4.0 * lane_to, 5), [4.0 * lane_to] * 3])
    return [[[5.0 * t, float(y)], [5.0 * t - 10.0, 8.0]] for t, y in enumerate(ys)]


@pytest.mark.parametrize(("lane_from", "lane_to", "complete"),
                         [(1, 0, False), (1, 2, False), (1, 1, False), (0, 0, False),
                          (2, 1, True), (0, 1, True)])
def test_posterior_picks_the_lane_the_robot_merges_into(lane_from, lane_to, complete):
    segment = (merged_segment if complete else highway_segment)(lane_from, lane_to)
    p = payload(HIGHWAY_SCENE, segment, [[20.0, 4.0]] * 5)
    absolute = inverse_planning.infer_intent(p, CONFIG)
    assert absolute.intents[np.argmax(absolute.posterior)] == lane_to
    assert absolute.posterior.max() > 0.95
    relative = inverse_planning.infer_intent(p, CONFIG, relative=True)
    assert relative.intents[np.argmax(relative.posterior)] == lane_to - lane_from


@pytest.mark.parametrize("goal", range(4))
def test_posterior_picks_the_goal_the_robot_heads_straight_for(goal):
    p = payload(OBSTACLE_SCENE, obstacle_segment([5.0, 5.5], GOALS[goal]), [[3.0, 4.0]] * 5)
    reading = inverse_planning.infer_intent(p, CONFIG)
    assert int(np.argmax(reading.posterior)) == goal
    assert reading.posterior.max() > 0.95


def test_prior_from_the_examples_shifts_the_posterior():
    # moving down from lane 0, still above lane 1: lanes 1 and 2 explain the moves equally
    p = payload(HIGHWAY_SCENE, highway_segment(0, 1), [[20.0, 4.0]] * 5)
    tie = inverse_planning.infer_intent(p, CONFIG).posterior
    assert tie[1] == pytest.approx(tie[2]) and tie[0] < 0.01
    for lane in (1, 2):
        shown = {**p, "examples": [lane_clip(0, lane)] * 4}
        reading = inverse_planning.infer_intent(shown, CONFIG)
        np.testing.assert_allclose(reading.prior, np.where(np.arange(3) == lane, 5, 1) / 7)
        assert int(np.argmax(reading.posterior)) == lane
    segment = obstacle_segment([5.0, 5.0], [5.0, 0.0])  # straight up, between goals 0 and 1
    p = payload(OBSTACLE_SCENE, segment, [[3.0, 4.0]] * 5)
    shown = {**p, "examples": [goal_clip([5.0, 5.0], 1)] * 4}
    before, after = (inverse_planning.infer_intent(q, CONFIG).posterior for q in (p, shown))
    assert before[0] == pytest.approx(before[1]) and after[1] > 0.8


@pytest.mark.parametrize(("scene", "n_intents"), [(HIGHWAY_SCENE, 3), (OBSTACLE_SCENE, 4)])
def test_each_worlds_intents_answer_the_same_questions(scene, n_intents):
    segment = highway_segment(1, 0) if scene["lanes"] else obstacle_segment([5, 5.5], GOALS[2])
    p = payload(scene, segment, [[20.0, 4.0], [3.0, 4.0]])
    intents = inverse_planning.payload_intents(p, CONFIG, relative=False)
    progress, candidates = intents.progress()
    assert progress.shape == (6, n_intents) and candidates.shape[:2] == (6, n_intents)
    assert len(intents.labels) == len(intents.feasible) == n_intents
    track = inverse_planning.robot_track(segment)
    assert intents.outcome(track) == (0 if scene["lanes"] else 2)
    direction, length = intents.course(intents.outcome(track), track[-1:], 1.0)(0, track[-1])
    assert direction.shape == (2,) and length >= 0


def test_relative_reading_moves_from_each_start_states_own_lane():
    p = payload(HIGHWAY_SCENE, highway_segment(1, 0), [[0.0, 8.0], [0.0, 4.0], [0.0, 0.0]])
    absolute = inverse_planning.predict_coarse(p, np.random.default_rng(0), QUIET, relative=False)
    relative = inverse_planning.predict_coarse(p, np.random.default_rng(0), QUIET, relative=True)
    assert np.all(np.diff(np.concatenate([[8.0], absolute[0, :, 1]])) < 0)  # all head for lane 0
    assert relative[0, -1, 1] >= 4.0 - 1e-9 and relative[0, -1, 1] < 8.0  # lane 2 -> lane 1
    assert relative[2, -1, 1] == pytest.approx(0.0)  # no lane left of lane 0: keeps it


def test_coarse_moves_forward_and_into_the_lane_without_overshooting():
    p = payload(HIGHWAY_SCENE, highway_segment(1, 0, steps=6), [[0.0, 0.6], [0.0, 5.0]])
    clicks = inverse_planning.predict_coarse(p, np.random.default_rng(0), QUIET)
    path = np.concatenate([inverse_planning.start_positions(p)[:, None], clicks], axis=1)
    track = inverse_planning.robot_track(p["segment"]["positions"])
    forward = forward_speed(track, p["dt_s"]) * p["dt_s"]
    np.testing.assert_allclose(np.diff(path[..., 0], axis=1), forward)
    lateral = inverse_planning.payload_intents(p, CONFIG, relative=False).step_m
    assert lateral == pytest.approx(4.0 / 4.6 * 0.5)
    np.testing.assert_allclose(path[0, :, 1], [0.6, 0.6 - lateral, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(np.diff(path[1, :, 1]), -lateral)
    p = payload(OBSTACLE_SCENE, obstacle_segment([5.0, 5.5], GOALS[3]), [[2.0, 2.0]])
    clicks = inverse_planning.predict_coarse(p, np.random.default_rng(0), QUIET)
    moves = np.diff(np.concatenate([[[2.0, 2.0]], clicks[0]]), axis=0)
    np.testing.assert_allclose(moves / np.linalg.norm(moves, axis=1, keepdims=True),
                               np.tile([[1, 1]], (3, 1)) / np.sqrt(2))
    np.testing.assert_allclose(np.linalg.norm(moves, axis=1), 0.4)


def _speed_and_angle_errors(p, predict, draws: int) -> tuple[np.ndarray, np.ndarray]:
    """Per draw, the first move's length ratio, and every move's angle error [deg]."""
    ratios, angles = [], []
    for seed in range(draws):
        clicks = predict(np.random.default_rng(seed))
        path = np.concatenate([inverse_planning.start_positions(p)[:, None], clicks], axis=1)
        moves = np.diff(path, axis=1).reshape(-1, 2)
        ratios.append(np.linalg.norm(moves[0]) / 0.4)
        angles.append(np.degrees(np.arctan2(moves[:, 1], moves[:, 0]) - np.pi / 4))
    return np.array(ratios), np.concatenate(angles)


@pytest.mark.parametrize("preset", ["coarse", "precise"])
def test_noise_statistics_match_the_config(preset):
    p = payload(OBSTACLE_SCENE, obstacle_segment([5.0, 5.5], GOALS[3]), [[1.5, 1.5]] * 2)
    actions = np.tile(np.array([0.8, 0.8]) / np.sqrt(2), (2, 3, 1))
    noise = getattr(MAP, f"{preset}_noise")
    if preset == "coarse":
        ratios, angles = _speed_and_angle_errors(
            p, lambda rng: inverse_planning.predict_coarse(p, rng, MAP), 1500)
    else:
        ratios, angles = _speed_and_angle_errors(
            p, lambda rng: inverse_planning.predict_from_actions(p, actions, rng, noise), 1500)
    assert ratios.mean() == pytest.approx(1.0, abs=0.01)
    assert ratios.std() == pytest.approx(noise.speed_weber_fraction.value, rel=0.1)
    assert angles.std() == pytest.approx(noise.direction_sd_deg.value, rel=0.1)


def test_observers_never_read_the_models_answers():
    bank = bank_with_examples()
    poisoned = copy.deepcopy(bank)
    rng = np.random.default_rng(5)
    for world in poisoned["worlds"].values():
        for trial in world["trials"]:
            for answer in (a for family in trial["predictions"].values() for a in family):
                answer["actions"] = rng.normal(size=(5, 3, 2)).tolist()
                answer["code"] = -1
            trial["cv_actions"] = rng.normal(size=(5, 3, 2)).tolist()
    read = trial_bank(bank)
    for world in read.data.worlds.values():
        p = simulated_payload(read, world.trials[0])
        assert not {"predictions", "cv_actions", "policy_actions"} & set(p)
    clicks = ["participant_id", "trial_id", "participant_click_x", "participant_click_y"]
    for preset in inverse_planning.PRESETS:
        clean = simulate_participants(read, preset, 4, 5, seed=3, show_progress=False)
        dirty = simulate_participants(trial_bank(poisoned), preset, 4, 5, seed=3,
                                      show_progress=False)
        assert clean[clicks].equals(dirty[clicks])
        assert not clean["ours_vx"].equals(dirty["ours_vx"])


@pytest.mark.parametrize("preset", inverse_planning.PRESETS)
def test_clicks_are_always_valid(preset):
    rng = np.random.default_rng(2)
    corners = {"highway": [[-9.5, -1.5], [59.5, 9.5], [20.0, 4.0], [59.0, -1.0], [0.0, 8.0]],
               "obstacle": [[0.2, 0.2], [9.8, 9.8], [5.0, 5.0], [9.9, 0.1], [1.0, 1.0]]}
    for _ in range(20):
        for scene in (HIGHWAY_SCENE, OBSTACLE_SCENE):
            if scene["lanes"]:
                seg = highway_segment(*rng.integers(3, size=2))
            else:
                seg = obstacle_segment(rng.uniform(2, 8, 2), GOALS[int(rng.integers(4))])
            p = payload(scene, seg, corners[scene["world"]])
            p["examples"] = [lane_clip(0, 2)] if scene["lanes"] else [goal_clip([5, 5], 2)]
            actions = rng.normal(scale=30.0, size=(5, 3, 2))  # too long, some off the scene
            _assert_valid(p, inverse_planning.predict(preset, p, rng, actions, CONFIG))


def test_config_typos_and_missing_sources_are_rejected(tmp_path):
    data = yaml.safe_load((REPO_ROOT / "study_configs" / "observers.yaml").read_text())
    assert load_observers(REPO_ROOT / "study_configs" / "observers.yaml") == CONFIG
    data["inference"]["betta"] = data["inference"].pop("beta")
    path = tmp_path / "observers.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"inference\.betta: Extra inputs"):
        load_observers(path)
    data["inference"]["beta"] = {"value": 2.0}
    del data["inference"]["betta"]
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"inference\.beta\.source: Field required"):
        load_observers(path)


def test_power_grows_with_n_for_coarse_bots():
    frame = simulate_participants(trial_bank(bank_with_examples()), "coarse", 40, 5, seed=0,
                                  show_progress=False, observers=MAP)
    assert len(frame) == 40 * 2 * 5 * 5 * 3
    means = participant_means(frame)
    assert (means["err_ours"] < means["err_vae"]).mean() > 0.9
    curve = power_curve(means, [3, 5, 20], reps=300, alpha=0.01)
    for _, group in curve.groupby("world"):
        assert group["power"].is_monotonic_increasing
        assert group["power"].iloc[-1] > 0.95


def test_instrument_check_runs_and_writes_its_files(tmp_path):
    table = instrument_check(trial_bank(bank_with_examples()), 5, n=6, seed=1, show_progress=False)
    assert list(table[["world", "reading"]].itertuples(index=False, name=None)) == [
        ("highway", "absolute"), ("highway", "relative"),
        ("obstacle", "absolute"), ("obstacle", "relative")]
    assert table["p_one_sided"].between(0, 1).all() and table["n_coarse"].eq(6).all()
    bank_path = tmp_path / "bank.json"
    bank_path.write_text(json.dumps(bank_with_examples()))
    summary = run_instrument(bank_path, 5, tmp_path / "out", n=4, seed=0, replications=3)
    for name in ("instrument.csv", "by_trial.csv", "replications.csv", "by_trial.png"):
        assert (tmp_path / "out" / name).is_file()
    assert all(0 <= rate <= 1 for rate in summary["pass_rate"].values())
    written = json.loads((tmp_path / "out" / "instrument.json").read_text())
    assert written["passed"] == summary["passed"] and set(written["passed"]) == {
        "highway", "obstacle"}
    assert written["observers"]["inference"]["beta"]["source"].startswith("Baker")
    assert (tmp_path / "out" / "separation.csv").is_file()


def test_simulated_participants_are_assigned_trials_as_the_server_assigns_them():
    bank = bank_with_examples()
    frame = simulate_participants(trial_bank(bank), "random", 7, 2, seed=3, show_progress=False)
    assert set(frame["world"]) == {"highway", "obstacle"}
    for world, rows in frame.groupby("world"):
        seen = rows.groupby("trial_id")["participant_id"].nunique()
        mains = [t["trial_id"] for t in bank["worlds"][world]["trials"] if t["kind"] == "main"]
        exposure = seen.reindex(mains, fill_value=0)
        # least used first: exposure never differs by more than one between trials
        assert exposure.sum() == 7 * 2 and exposure.max() - exposure.min() <= 1
    firsts = frame[frame["world_position"] == 0].groupby("participant_id")["world"].first()
    assert abs((firsts == "highway").sum() - (firsts == "obstacle").sum()) <= 1


def test_trial_contrast_counts_every_participant_who_saw_a_trial():
    frames = population_frames(trial_bank(bank_with_examples()), 6, 5, seed=2, observers=CONFIG,
                               show_progress=False)
    table = trial_contrast(frames)
    for _world, rows in table.groupby("world"):
        # 6 participants x 5 of 6 trials, least seen first: every trial seen by both populations
        assert len(rows) == 6
        assert rows["coarse_participants"].sum() == rows["precise_participants"].sum() == 6 * 5
    assert table[["coarse_diff", "precise_diff"]].notna().all().all()
    first = table.iloc[0]
    rows = frames["coarse"][frames["coarse"]["trial_id"] == first["trial_id"]]
    assert first["coarse_diff"] == pytest.approx((rows["err_ours"] - rows["err_vae"]).mean())


def test_separation_says_where_models_and_observers_differ():
    gaps = separation(trial_bank(bank_with_examples()), seed=0).set_index(["world", "start_kind"])
    for world in ("highway", "obstacle"):
        kinds = gaps.loc[world]
        parts = kinds.drop(index="all")
        assert kinds.loc["all", "n_starts"] == parts["n_starts"].sum()
        for col in ("ours_vs_vae", "coarse_vs_precise", "coarse_diff", "precise_diff"):
            weighted = (parts[col] * parts["n_starts"]).sum() / parts["n_starts"].sum()
            assert kinds.loc["all", col] == pytest.approx(weighted)
        assert (kinds["ours_vs_vae"] > 0).all()  # the fixture's VAE drifts off Ours' answer
    # where the two models answer alike, no observer can favour either
    same = bank_with_examples()
    for world in same["worlds"].values():
        for trial in world["trials"]:
            trial["predictions"]["vae"][0]["actions"] = trial["predictions"]["ours"][0]["actions"]
    alike = separation(trial_bank(same), seed=0)
    assert np.allclose(alike[["ours_vs_vae", "coarse_diff", "precise_diff"]], 0.0)


def test_instrument_command_prints_the_table(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from app.cli import cli
    from app.settings import get_settings

    bank = tmp_path / "bank.json"
    bank.write_text(json.dumps(bank_with_examples()))
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(tmp_path / "var"))
    get_settings.cache_clear()
    try:
        result = CliRunner().invoke(cli, ["instrument", "--n", "4", "--replications", "2",
                                          "--bank", str(bank), "--out", str(tmp_path / "o"),
                                          "--goal-reps", "20", "--no-search"])
    finally:
        get_settings.cache_clear()
    written = json.loads((tmp_path / "o" / "instrument.json").read_text())
    goal = json.loads((tmp_path / "o" / "goal.json").read_text())
    missed = [w for w, met in goal["goal_met"].items() if not met
              and w not in goal["exploratory"]]
    assert result.exit_code == (1 if missed else 0), result.output
    assert "obstacle: EXPLORATORY" in result.output  # paper_study.yaml marks it
    assert f"{'highway':<14}{'all':<18}{'family':<17}" in result.output
    assert f"{'highway':<14}absolute" in result.output
    assert f"{'obstacle':<14}relative" in result.output
    assert "start kind" in result.output and f"{'obstacle':<14}all" in result.output
    assert "pass rate" in result.output and written["replications"] == 2
    grid = json.loads((tmp_path / "o" / "grid.json").read_text())
    assert grid["seed_pairs"] == [0, 1] and (tmp_path / "o" / "grid.png").is_file()
    assert "pass rate per seed pair" in result.output and "goal (pass rate >= 0.8" in result.output
    for world in ("highway", "obstacle"):
        for level in grid["noise_levels"]:
            assert f"{world:<14}{level:<16}" in result.output


def test_a_move_that_would_overshoot_a_narrow_scene_turns_along_it():
    # towards the centre from below it, 8 m overshoots the road's far edge (y 10): before the
    # server's click check ran on simulated answers, such a click was made and never refused
    scene = {"bounds": {"x_min_m": -10.0, "x_max_m": 60.0, "y_min_m": -2.0, "y_max_m": 10.0}}
    origin = np.array([25.0, 2.5])
    point = inverse_planning.valid_move({"scene": scene}, origin, np.array([0.0, 1.0]), 8.0)
    assert inverse_planning.inside_bounds({"scene": scene}, point)
    assert np.hypot(*(point - origin)) == pytest.approx(8.0)
