"""Recorded worlds: importing INTERACTION recordings (both layouts), the scene, the held-out
split, malformed recordings, and the World protocol's rules taken from the data."""

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from app.bank.build import clip_of
from app.configio import ConfigError
from app.data.scene import Bounds, Scene
from app.data.trajectory import ROBOT, Covered, TrajectorySet
from app.data.windows import split_by_trajectory
from app.layout import Layout
from app.recordings.generated import generate_study_recordings
from app.recordings.importer import (
    LABEL_NAMES,
    UnusableRecordings,
    agent_sizes,
    import_recordings,
)
from app.recordings.lanelet_map import LaneLine
from app.recordings.pairs import Pair, turn_label
from app.recordings.scene import SceneFrame, row_runs, scene_lines, simplify
from app.recordings.tracks import TrackFileError
from app.study.trials import TrialRecord
from app.worlds.recorded import RecordedWorld
from app.worlds.registry import World, build_world
from tests.recordings.scenarios import INTERSECTION, ROUNDABOUT, recorded_config


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Path:
    """Generated (not real) recordings of both scenarios: a v1.2 roundabout, a v1.0 intersection."""
    root = tmp_path_factory.mktemp("recordings")
    generate_study_recordings(root / "INTERACTION", seconds=120.0)
    return root


@pytest.fixture(scope="module")
def imported(recordings, tmp_path_factory) -> dict:
    """Both worlds imported into one data dir: each one's trajectories and meta, and the layout."""
    layout = Layout(tmp_path_factory.mktemp("var"), recordings)
    out = {"layout": layout}
    for name, scenario in (("roundabout", ROUNDABOUT), ("intersection", INTERSECTION)):
        import_recordings(name, recorded_config(scenario), layout)
        out[name] = TrajectorySet.load(layout.trajectories(name))
        out[name + "_meta"] = json.loads(layout.trajectories_meta(name).read_text())
    return out


def test_v12_val_cases_are_held_out_and_v10_holds_out_each_recordings_end(imported):
    roundabout, meta = imported["roundabout"], imported["roundabout_meta"]
    assert meta["source"] == f"INTERACTION {ROUNDABOUT} (v1.2)"
    assert meta["pairs"]["held_out"] == int(roundabout.held_out.sum()) > 0
    assert meta["pairs"]["train"] == int((~roundabout.held_out).sum()) > 0
    assert not roundabout.held_out[: meta["pairs"]["train"]].any()  # training pairs first
    intersection = imported["intersection_meta"]
    assert intersection["source"] == f"INTERACTION {INTERSECTION} (v1.0)"
    assert intersection["pairs"]["held_out"] > 0 and intersection["pairs"]["train"] > 0
    assert set(intersection["input_sha256"]) >= {
        f"recorded_trackfiles/{INTERSECTION}/vehicle_tracks_000.csv", f"maps/{INTERSECTION}.osm"}


def test_no_pair_shows_its_two_cars_on_top_of_each_other(imported):
    dropped = 0
    for world in ("roundabout", "intersection"):
        trajs, meta = imported[world], imported[f"{world}_meta"]
        gaps = np.linalg.norm(trajs.positions[:, :, 0] - trajs.positions[:, :, 1], axis=-1)
        side_by_side = trajs.sizes[:, :, 1].mean(axis=1)  # the mean of the two cars' widths
        assert (gaps.min(axis=1) >= side_by_side - 1e-6).all()
        dropped += sum(meta["pairs_dropped_overlapping"].values())
    assert dropped > 0  # the generator's cars do pass through each other


def recorded_sizes(recordings: Path) -> set[tuple[float, float]]:
    """Every (length, width) the generated track files give a car."""
    sizes = set()
    for path in (recordings / "INTERACTION").rglob("*.csv"):
        with open(path, newline="") as fh:
            sizes |= {(float(row["length"]), float(row["width"])) for row in csv.DictReader(fh)
                      if row.get("agent_type") == "car"}
    return sizes


def test_each_pair_keeps_its_two_vehicles_recorded_sizes(imported, recordings):
    known = recorded_sizes(recordings)
    for world in ("roundabout", "intersection"):
        sizes = imported[world].sizes
        assert sizes.shape == (len(imported[world]), 2, 2)
        assert {(round(float(a), 3), round(float(b), 3)) for a, b in sizes.reshape(-1, 2)} <= known
        lengths = sizes[..., 0]
        assert lengths.min() < 4.6 < np.median(lengths) + 0.5 and lengths.max() > 8.0  # buses
        # the trajectories file keeps them
        again = TrajectorySet.load(imported["layout"].trajectories(world)).sizes
        assert np.array_equal(again, sizes)


def test_a_log_without_sizes_draws_the_configs_agent():
    pair = Pair("r", 1, 2, 0, np.zeros((3, 2, 2)), np.zeros((3, 2)), np.zeros((3, 2)),
                np.array([[np.nan, np.nan], [12.0, 2.5]]))
    looks = recorded_config(ROUNDABOUT, agent={"kind": "car", "length_m": 4.2, "width_m": 1.8})
    assert agent_sizes(pair, looks).tolist() == [[4.2, 1.8], [12.0, 2.5]]


def test_sizes_reach_the_trial_payload_and_a_simulated_clip_has_none(imported):
    trajs = imported["intersection"]
    def as_stored(i: int) -> list[list[float]]:  # centimetres, no float32 digits
        return [[round(float(v), 2) for v in agent] for agent in trajs.sizes[i]]

    sized = clip_of(trajs, 0, 0, 4, "robot_turn")
    assert sized.sizes == as_stored(0)
    assert sized.shown()["sizes"] == sized.sizes and "sizes" in sized.model_dump()
    plain = clip_of(dataclasses.replace(trajs, sizes=None), 0, 0, 4, "robot_turn")
    assert set(plain.shown()) == {"positions", "headings"}  # as before sizes existed
    assert "sizes" not in plain.model_dump() and "sizes" not in plain.model_dump_json()
    segment = clip_of(trajs, 1, 0, 4, "robot_turn")
    trial = TrialRecord(trial_id="t", world="intersection", kind="main", source_index=1,
                        segment_start=0, robot_label=0, examples=[sized], segment=segment,
                        start_states=[], model_input=[], predictions={}, cv_actions=[],
                        policy_actions=[], clip_sha256="")
    shown = trial.browser_payload()
    assert shown["segment"]["sizes"] == as_stored(1)
    assert shown["examples"][0]["sizes"] == sized.sizes


def test_virtual_lanelet_borders_are_not_drawn():
    frame = SceneFrame(np.zeros(2))
    bounds = Bounds(x_min_m=-20, x_max_m=20, y_min_m=-20, y_max_m=20)
    across = np.array([[-10.0, 0.0], [10.0, 0.0]])
    lines = [LaneLine(kind, sub, across + [0, k]) for k, (kind, sub) in enumerate(
        [("virtual", ""), ("line_thin", "dashed"), ("zebra_marking", ""), ("curbstone", "")])]
    drawn = scene_lines(lines, frame, bounds)
    assert [(line.kind, line.dashed) for line in drawn] == [
        ("border", True), ("border", False), ("kerb", False)]


def test_pairs_are_sampled_every_dt_and_labelled(imported):
    trajs = imported["roundabout"]
    assert trajs.dt_s == 0.4 and trajs.positions.shape[1:] == (10, 2, 2)  # 4 s = 9 steps
    assert trajs.label_names == LABEL_NAMES
    steps = np.linalg.norm(np.diff(trajs.positions[:, :, ROBOT], axis=1), axis=-1)
    assert 1.0 < np.median(steps) / trajs.dt_s < 20.0  # cars, in m/s
    assert set(np.unique(trajs.labels["robot_turn"])) == {0, 1, 2}


def test_the_scene_is_the_map_mirrored_with_the_driven_area(imported):
    scene = imported["roundabout"].scene
    recorded = scene.recorded
    assert recorded.source.startswith("INTERACTION") and recorded.view_span_m == 60.0
    kinds = {line.kind for line in recorded.lines}
    assert {"kerb", "border"} <= kinds and any(line.dashed for line in recorded.lines)
    cells = sum(b - a + 1 for _, a, b in recorded.driven.runs)
    assert 50 < cells < 0.8 * (scene.bounds.x_max_m - scene.bounds.x_min_m) \
        * (scene.bounds.y_max_m - scene.bounds.y_min_m) / recorded.driven.cell_m ** 2
    b = scene.bounds
    points = imported["roundabout"].positions.reshape(-1, 2)
    assert (points[:, 0] >= b.x_min_m).all() and (points[:, 1] <= b.y_max_m).all()


def test_a_left_turn_on_the_map_is_a_left_turn_on_screen():
    quarter = np.linspace(0, np.pi / 2, 12)
    track = np.stack([np.cos(quarter - np.pi / 2), 1 + np.sin(quarter - np.pi / 2)], axis=1) * 20
    assert LABEL_NAMES["robot_turn"][turn_label(track, 30.0)] == "left"  # counter-clockwise, y up
    screen = SceneFrame(np.zeros(2)).points(track)
    moves = np.diff(screen, axis=0)
    turn = moves[:-1, 0] * moves[1:, 1] - moves[:-1, 1] * moves[1:, 0]
    assert (turn < 0).all()  # drawn with y down, counter-clockwise on screen again
    assert SceneFrame.headings(np.array([0.5]))[0] == -0.5


def test_a_simulated_scene_serialises_without_the_recorded_part():
    scene = Scene(world="w", dt_s=0.5, frame="f", agents=[],
                  bounds=Bounds(x_min_m=0, x_max_m=1, y_min_m=0, y_max_m=1))
    assert "recorded" not in scene.model_dump() and "recorded" not in scene.model_dump_json()


def test_every_checkpoint_tests_on_the_held_out_recordings(imported):
    trajs = imported["roundabout"]
    split = split_by_trajectory(len(trajs), 0.15, 0.15, seed=4, held_out=trajs.held_out)
    assert split["test"].tolist() == np.flatnonzero(trajs.held_out).tolist()
    assert not set(split["val"]) & set(split["test"]) and len(split["val"]) > 0
    assert sorted([*split["train"], *split["val"], *split["test"]]) == list(range(len(trajs)))


def test_a_malformed_recording_names_file_line_column_and_writes_nothing(recordings, tmp_path):
    broken = tmp_path / "rec" / "INTERACTION"
    broken.mkdir(parents=True)
    for sub in ("train", "val", "maps"):
        (broken / sub).symlink_to(recordings / "INTERACTION" / sub)
    (broken / "val").unlink()
    lines = (recordings / "INTERACTION" / "val" / f"{ROUNDABOUT}_val.csv").read_text().splitlines()
    cells = lines[7].split(",")
    cells[5] = "east"  # column x
    lines[7] = ",".join(cells)
    (broken / "val").mkdir()
    (broken / "val" / f"{ROUNDABOUT}_val.csv").write_text("\n".join(lines) + "\n")
    layout = Layout(tmp_path / "var", tmp_path / "rec")
    with pytest.raises(TrackFileError, match=rf"{ROUNDABOUT}_val.csv:8: column 'x': expected a "
                                             r"number, found 'east'"):
        import_recordings("roundabout", recorded_config(ROUNDABOUT), layout)
    assert not (tmp_path / "var").exists()


def test_too_few_pairs_and_a_dt_off_the_recordings_grid_say_what_to_change(recordings, tmp_path):
    layout = Layout(tmp_path, recordings)
    with pytest.raises(UnusableRecordings, match="dt_s: 0.25 s is not a whole number"):
        import_recordings("roundabout", recorded_config(ROUNDABOUT, dt_s=0.25, window_s=4.0),
                          layout)
    with pytest.raises(UnusableRecordings, match="only 0 training pairs .* shorten window_s"):
        import_recordings("roundabout", recorded_config(ROUNDABOUT, pair_max_distance_m=0.5),
                          layout)
    with pytest.raises(UnusableRecordings, match="source.path: .* does not exist"):
        nowhere = recorded_config(ROUNDABOUT).source.model_copy(update={"path": "nowhere"})
        import_recordings("roundabout", recorded_config(ROUNDABOUT).model_copy(
            update={"source": nowhere}), layout)
    assert not layout.trajectories("roundabout").exists()


def test_a_window_too_short_for_a_trial_is_a_config_error():
    with pytest.raises(ValueError, match="window_s: 2 s holds 5 steps"):
        recorded_config(ROUNDABOUT, window_s=2.0)


# ---------------------------------------------------------------- the World protocol


@pytest.fixture(scope="module")
def world(imported) -> RecordedWorld:
    built = RecordedWorld("roundabout", recorded_config(ROUNDABOUT))
    built.prepare(imported["layout"])
    return built


def test_a_recorded_world_implements_the_protocol(world):
    assert isinstance(world, World)


def test_from_the_robots_own_state_the_policy_is_what_happened_next(world, imported):
    trajs = imported["roundabout"]
    i, end = int(np.flatnonzero(trajs.held_out)[3]), 4
    positions = np.round(trajs.positions[i, end].astype(np.float64), 3)
    heading = float(trajs.headings[i, end, ROBOT])
    actions = world.robot_policy_actions(positions, heading, 8.0, np.zeros(2), {}, 3,
                                         np.random.default_rng(0))
    truth = np.diff(trajs.positions[i, end: end + 4, ROBOT].astype(np.float64), axis=0) / 0.4
    assert np.allclose(actions, truth, atol=1e-4)


def test_with_no_recorded_state_near_the_policy_holds_heading_and_speed(world):
    far = np.array([[1e4, 1e4], [0.0, 0.0]])
    actions = world.robot_policy_actions(far, np.pi / 2, 5.0, np.zeros(2), {}, 3,
                                         np.random.default_rng(0))
    assert np.allclose(actions, [[0.0, 5.0]] * 3, atol=1e-9)


def test_segments_end_only_where_the_robot_moves(world):
    moving = np.stack([np.arange(12.0) * 2, np.zeros(12)], axis=1)
    stopped = moving.copy()
    stopped[6:] = stopped[6]  # stands from step 6
    assert world.visible_ends(moving, np.arange(1, 9)).tolist() == list(range(1, 9))
    assert world.visible_ends(stopped, np.arange(1, 9)).tolist() == [1, 2, 3]


def test_starts_lie_where_recorded_robots_drove_the_robots_way(world):
    scene = world_scene()
    segment = np.array([[[0.0, 0.0], [30.0, 30.0]], [[2.0, 0.0], [30.0, 30.0]]])
    covered = Covered(np.array([[4.0, 0.0], [4.0, 1.0], [7.0, 0.0], [9.0, 0.0], [30.0, 0.0]]),
                      np.array([0.1, np.pi, -0.2, 0.0, 0.0]))
    pools = world.data_start_candidates(scene, segment, covered, reach=3.0)
    assert pools["near"].tolist() == [0]  # [4, 1] heads the other way
    assert pools["far"].tolist() == [2]  # [9, 0] is beyond twice the reach


def world_scene() -> Scene:
    from app.data.scene import AgentShape

    car = AgentShape(name="robot", kind="car", length_m=4.6, width_m=1.9, color="#000000")
    return Scene(world="roundabout", dt_s=0.4, frame="f", agents=[car, car],
                 bounds=Bounds(x_min_m=-50, x_max_m=50, y_min_m=-50, y_max_m=50))


def test_the_registry_builds_recorded_worlds_from_their_yaml(tmp_path):
    path = tmp_path / "worlds" / "yard.yaml"
    path.parent.mkdir()
    path.write_text("kind: recorded\nsource: {format: interaction, path: x, scenario: y}\n")
    assert isinstance(build_world("yard", path), RecordedWorld)
    path.write_text("lanes_count: 3\n")
    with pytest.raises(ConfigError, match="must be `kind: recorded`"):
        build_world("yard", path)
    with pytest.raises(ConfigError, match="unknown world 'nowhere'"):
        build_world("nowhere", tmp_path / "nowhere.yaml")
    with pytest.raises(ConfigError, match="is not a world name"):
        build_world("../etc")


def test_lines_are_simplified_and_cells_run_length_coded():
    line = np.stack([np.linspace(0, 10, 50), np.zeros(50)], axis=1)
    assert simplify(line, 0.1).tolist() == [[0.0, 0.0], [10.0, 0.0]]
    bent = np.array([[0.0, 0.0], [5.0, 1.0], [10.0, 0.0]])
    assert len(simplify(bent, 0.1)) == 3
    grid = np.array([[0, 1, 1, 0, 1], [0, 0, 0, 0, 0], [1, 1, 1, 1, 1]], dtype=bool)
    assert row_runs(grid) == [[0, 1, 2], [0, 4, 4], [2, 0, 4]]


def test_the_hallway_example_imports_generated_lab_logs(tmp_path):
    from app.recordings.synthetic_logs import generate_logs
    from app.settings import REPO_ROOT

    generate_logs(tmp_path / "rec" / "lab" / "logs.csv", recordings=8, seconds=60.0, seed=2)
    layout = Layout(tmp_path / "var", tmp_path / "rec")
    world = build_world("hallway", REPO_ROOT / "study_configs" / "worlds" / "hallway.yaml")
    meta = world.import_recordings(layout).meta
    assert meta["recordings"] == {"train": 6, "val": 2} and meta["pairs"]["held_out"] > 0
    trajs = TrajectorySet.load(layout.trajectories("hallway"))
    assert trajs.positions.shape[1:] == (16, 2, 2)  # 80 samples of 8 s, every 5th: 15 steps
    world.prepare(layout)
    robot = trajs.positions[:, :, ROBOT].astype(np.float64)
    usable = [len(world.visible_ends(track, np.arange(5, 14))) for track in robot]
    assert sum(usable) > 0.5 * 9 * len(robot)  # a walking robot is under way most of the time
    assert [a.kind for a in trajs.scene.agents] == ["disc", "disc"]


def test_serve_prepare_without_recordings_says_where_they_go(tmp_path):
    from app.http.preflight import NotServable
    from app.main import ready_to_serve
    from app.settings import REPO_ROOT, Settings

    settings = Settings(data_dir=tmp_path / "var", configs_dir=REPO_ROOT / "study_configs",
                        admin_token="t" * 32)
    with pytest.raises(NotServable, match=r"interaction_study: its bundle cannot be built: "
                                          r"source.path: .*recordings/INTERACTION does not exist"
                                          r".*tomstudy generate-recordings"):
        ready_to_serve(settings, "127.0.0.1", 1, ["interaction_study"], prepare=True,
                       say=lambda line: None)
    assert not (tmp_path / "var" / "data").exists()
