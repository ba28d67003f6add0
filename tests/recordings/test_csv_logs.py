"""Lab logs: the generic CSV reads back into recordings, every malformed file gets its exact
error, empty velocities come from positions, and role-aware pairs pair a robot with a human."""

import csv
import hashlib
from pathlib import Path

import numpy as np
import pytest

from app.recordings import pairs as px
from app.recordings.csv_logs import RecordingError, read_line_file, read_logs
from app.recordings.synthetic_logs import generate_logs

HEADER = "recording,agent_id,time_s,x_m,y_m,vx_mps,vy_mps,role"
ORDER = "[recording,]agent_id,time_s,x_m,y_m,vx_mps,vy_mps,role[,heading_rad,length_m,width_m]"
# lines 2-7: a robot driving east at 1 m/s, a person walking north with empty velocity cells
GOOD = ["s1,bot,0.0,0.0,0.0,1.0,0.0,robot", "s1,ann,0.0,3.0,0.0,,,human",
        "s1,bot,0.1,0.1,0.0,1.0,0.0,robot", "s1,ann,0.1,3.0,0.1,,,human",
        "s1,bot,0.2,0.2,0.0,1.0,0.0,robot", "s1,ann,0.2,3.0,0.2,,,human"]


def _write(path: Path, header: str, rows: list[str]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join([header, *rows]) + "\n" if header else "")
    return path


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("logs") / "lab.csv"


@pytest.fixture(scope="module")
def logs(generated):
    generate_logs(generated, recordings=3, seconds=20.0, seed=1)
    return read_logs(generated)


# ---------------------------------------------------------------- reading back


def test_generated_file_reads_back_with_its_recordings_agents_and_roles(generated, logs):
    assert logs.dt_s == 0.1
    assert [r.name for r in logs.recordings] == ["generated_001", "generated_002",
                                                 "generated_003"]
    assert logs.files == {"lab.csv": hashlib.sha256(generated.read_bytes()).hexdigest()}
    for rec in logs.recordings:
        assert rec.source == generated
        assert [(t.track_id, t.name, t.agent_type) for t in rec.tracks] == [
            (1, "robot_1", "robot"), (2, "person_1", "human")]
        for track in rec.tracks:
            assert track.frames.tolist() == list(range(201))
            assert track.xy.shape == track.v.shape == (201, 2)
        robot, person = rec.tracks
        assert (robot.length_m, robot.width_m) == (0.7, 0.5)
        assert np.isnan(person.length_m) and np.isnan(person.width_m)


def test_velocities_and_headings_are_the_files_cells(generated, logs):
    with open(generated, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["recording"] == "generated_002"
                and r["agent_id"] == "person_1"]
    person = logs.recordings[1].tracks[1]
    np.testing.assert_array_equal(person.v, [[float(r["vx_mps"]), float(r["vy_mps"])]
                                             for r in rows])
    np.testing.assert_array_equal(person.psi, [float(r["heading_rad"]) for r in rows])
    np.testing.assert_array_equal(person.xy, [[float(r["x_m"]), float(r["y_m"])] for r in rows])


def test_generated_walkers_move_at_walking_speeds_inside_the_room(logs):
    for rec in logs.recordings:
        robot, person = (np.hypot(t.v[:, 0], t.v[:, 1]) for t in rec.tracks)
        assert robot.mean() > 0.4 and robot.max() <= 0.8 + 0.002  # cells have 3 decimals
        assert person.mean() > 0.7 and person.max() <= 1.2 + 0.002
        for track in rec.tracks:
            assert track.xy.min() >= 0 and (track.xy.max(axis=0) <= [12.0, 8.0]).all()


def test_same_seed_same_bytes(tmp_path, generated, logs):
    again = generate_logs(tmp_path / "again.csv", recordings=3, seconds=20.0, seed=1)
    assert (tmp_path / "again.csv").read_bytes() == generated.read_bytes()
    assert again["generated"] == "NOT REAL DATA"
    generate_logs(tmp_path / "other.csv", recordings=3, seconds=20.0, seed=2)
    assert (tmp_path / "other.csv").read_bytes() != generated.read_bytes()


def test_empty_velocity_cells_are_position_differences_centred_where_possible(tmp_path):
    rows = [*GOOD, "s1,ann,0.4,3.0,0.6,,,human", "s1,ann,0.5,3.0,1.0,,,human"]  # 0.3 s missing
    (rec,) = read_logs(_write(tmp_path / "v.csv", HEADER, rows)).recordings
    bot, ann = rec.tracks
    np.testing.assert_array_equal(bot.v, [[1.0, 0.0]] * 3)  # given cells are kept
    assert ann.frames.tolist() == [0, 1, 2, 4, 5]  # the gap stays a gap
    # first: forward; 0.1 s: centred; 0.2 s and 0.4 s: one-sided (the gap); last: backward
    np.testing.assert_allclose(ann.v[:, 1], [1.0, 1.0, 1.0, 4.0, 4.0])
    np.testing.assert_allclose(ann.v[:, 0], 0.0)


def test_derived_velocities_match_the_generators_on_smooth_paths(tmp_path, logs):
    generate_logs(tmp_path / "nov.csv", recordings=3, seconds=20.0, seed=1, velocities=False)
    derived = read_logs(tmp_path / "nov.csv")
    for given, rec in zip(logs.recordings, derived.recordings, strict=True):
        for a, b in zip(given.tracks, rec.tracks, strict=True):
            np.testing.assert_array_equal(a.xy, b.xy)
            error = np.abs(a.v - b.v)  # m/s, against walking speeds of 0.8 and 1.2
            assert error.mean() < 0.01 and error.max() < 0.15  # the worst: where a turn starts


def test_file_without_recording_column_is_one_recording_named_after_it(tmp_path):
    rows = [r.split(",", 1)[1] for r in GOOD]
    logs = read_logs(_write(tmp_path / "morning_run.csv", HEADER.split(",", 1)[1], rows))
    assert [r.name for r in logs.recordings] == ["morning_run"]


def test_folder_reads_its_csv_files_in_name_order_with_optional_columns(tmp_path):
    trailing = ",heading_rad,length_m,width_m"
    _write(tmp_path / "b.csv", HEADER + trailing, [r + ",0.5,," for r in GOOD])
    _write(tmp_path / "a.csv", HEADER, [r.replace("s1,", "s0,") for r in GOOD])
    (tmp_path / "notes.txt").write_text("not a log")
    logs = read_logs(tmp_path)
    assert [(r.name, r.source.name) for r in logs.recordings] == [("s0", "a.csv"),
                                                                  ("s1", "b.csv")]
    assert list(logs.files) == ["a.csv", "b.csv"]  # named in the folder: any machine alike
    np.testing.assert_array_equal(logs.recordings[1].tracks[0].psi, 0.5)
    assert np.isnan(logs.recordings[0].tracks[0].psi).all()


def test_times_need_not_start_at_zero_nor_be_sorted(tmp_path):
    rows = [r.replace(",0.", ",1700000000.", 1) for r in GOOD]
    rows = rows[::-1]
    (rec,) = read_logs(_write(tmp_path / "t.csv", HEADER, rows)).recordings
    assert [t.name for t in rec.tracks] == ["ann", "bot"]  # order of first appearance
    assert rec.tracks[1].frames.tolist() == [0, 1, 2]
    np.testing.assert_array_equal(rec.tracks[1].xy[:, 0], [0.0, 0.1, 0.2])


# ---------------------------------------------------------------- malformed files


def _case(tmp_path: Path, name: str) -> Path:
    """A file (or folder) with one documented mistake."""
    no_vy = [r.rsplit(",", 2)[0] + "," + r.rsplit(",", 1)[1] for r in GOOD]
    two_dt = [HEADER, "s2,bot,0.0,0,0,1,0,robot", "s2,bot,0.2,0,0,1,0,robot"]
    folders = {
        "two_dts": {"a.csv": [HEADER, *GOOD], "b.csv": two_dt},
        "recording_in_two_files": {"a.csv": [HEADER, *GOOD],
                                   "b.csv": [HEADER, "s1,zed,0.0,0,0,1,0,robot"]},
        "file_named_like_a_recording": {"s1.csv": [HEADER.split(",", 1)[1],
                                                   *[r.split(",", 1)[1] for r in GOOD]],
                                        "s2.csv": [HEADER, "s1,zed,0.0,0,0,1,0,robot"]},
    }
    if name in folders:
        for file, lines in folders[name].items():
            _write(tmp_path / name / file, lines[0], lines[1:])
        return tmp_path / name
    files = {
        "missing_column": (HEADER.replace(",vy_mps", ""), no_vy),
        "reordered_column": (HEADER.replace("x_m,y_m", "y_m,x_m"), GOOD),
        "unknown_column": (HEADER + ",speed", [r + ",1" for r in GOOD]),
        "unknown_column_inside": (HEADER.replace(",x_m", ",speed,x_m"), GOOD),
        "optional_columns_reordered": (HEADER + ",width_m,length_m", [r + ",," for r in GOOD]),
        "non_number": (HEADER, [*GOOD[:2], GOOD[2].replace("0.1,0.0,1.0", "abc,0.0,1.0")]),
        "nan": (HEADER, [GOOD[0], GOOD[1].replace("3.0,0.0", "nan,0.0")]),
        "inf": (HEADER, [*GOOD[:2], GOOD[2].replace(",1.0,0.0,robot", ",inf,0.0,robot")]),
        "off_grid_time": (HEADER, [*GOOD[:4], GOOD[4].replace("0.2,0.2", "0.25,0.2"), GOOD[5]]),
        "duplicate_time": (HEADER, [*GOOD, GOOD[2]]),
        "role_change": (HEADER, [*GOOD[:3], GOOD[3].replace("human", "robot"), *GOOD[4:]]),
        "empty_file": ("", []),
        "header_only": (HEADER, []),
        "long_agent_id": (HEADER, [GOOD[0].replace("bot", "b" * 65)]),
        "capitalised_role": (HEADER, [GOOD[0].replace("robot", "Robot")]),
        "half_velocity": (HEADER, [GOOD[0].replace("1.0,0.0,robot", "1.0,,robot")]),
        "velocity_with_no_neighbour": (HEADER, [*GOOD, "s1,cat,0.0,5,5,,,pet",
                                                "s1,cat,0.2,5,5,,,pet"]),
        "short_row": (HEADER, [GOOD[0], "s1,bot,0.1,0.1"]),
        "long_row": (HEADER, [GOOD[0], GOOD[1] + ",x"]),
        "size_changes": (HEADER + ",length_m", [GOOD[0] + ",0.7", GOOD[2] + ",0.8"]),
        "no_step": (HEADER, GOOD[:2]),
    }
    header, rows = files[name]
    return _write(tmp_path / f"{name}.csv", header, rows)


MALFORMED = {
    "missing_column": f"missing_column.csv:1: column 'vy_mps': missing from the header "
                      f"(expected {ORDER})",
    "reordered_column": f"reordered_column.csv:1: column 'y_m': found as column 4 where 'x_m' "
                        f"is expected (columns reordered; expected {ORDER})",
    "unknown_column": "unknown_column.csv:1: column 'speed': not a documented column (column 9 "
                      "of the header; after 'role' only heading_rad, length_m, width_m may "
                      "follow)",
    "unknown_column_inside": f"unknown_column_inside.csv:1: column 'speed': not a documented "
                             f"column (column 4 of the header; expected {ORDER})",
    "optional_columns_reordered": "optional_columns_reordered.csv:1: column 'length_m': column "
                                  "10 of the header repeats or reorders the optional columns "
                                  "(expected heading_rad, length_m, width_m, in this order)",
    "non_number": "non_number.csv:4: column 'x_m': expected a number, found 'abc'",
    "nan": "nan.csv:3: column 'x_m': 'nan' is not finite: expected a number",
    "inf": "inf.csv:4: column 'vx_mps': 'inf' is not finite: expected a number",
    "off_grid_time": "off_grid_time.csv:6: column 'time_s': 0.25 s is 2.500 steps of 0.1 s "
                     "after the recording's first time 0 s: every time must be a whole number "
                     "of steps (within 1%); put logs with jittered clocks on a regular grid "
                     "first",
    "duplicate_time": "duplicate_time.csv:8: column 'time_s': agent 'bot' has two rows at "
                      "0.1 s (the other is line 4): one row per agent and time",
    "role_change": "role_change.csv:5: column 'role': agent 'ann' is 'robot' here but 'human' "
                   "at line 3: an agent keeps one role",
    "empty_file": f"empty_file.csv:1: empty file: expected a header line {ORDER}",
    "header_only": "header_only.csv:2: no data rows after the header",
    "long_agent_id": "long_agent_id.csv:2: column 'agent_id': 65 characters: expected an id of "
                     "1 to 64 characters",
    "capitalised_role": "capitalised_role.csv:2: column 'role': 'Robot' is not a role: expected "
                        "robot, human or another lower-case word such as pedestrian",
    "half_velocity": "half_velocity.csv:2: column 'vy_mps': empty while the other velocity "
                     "cell is not: give vx_mps and vy_mps, or leave both empty",
    "velocity_with_no_neighbour": "velocity_with_no_neighbour.csv:8: column 'vx_mps': empty, "
                                  "and agent 'cat' has no sample one step before or after "
                                  "this one to take its velocity from: give vx_mps and vy_mps "
                                  "here",
    "short_row": "short_row.csv:3: column 'y_m': missing: the row has 4 fields where the "
                 "header has 8",
    "long_row": "long_row.csv:3: column 9: the row has 9 fields where the header has 8 (quote "
                "a value that holds a comma)",
    "size_changes": "size_changes.csv:3: column 'length_m': agent 'bot' is 0.8 m here but "
                    "0.7 m at line 2: one size per agent",
    "no_step": "no_step.csv:2: column 'time_s': no agent has two samples at different times, "
               "so the time step cannot be inferred",
    "two_dts": "two_dts/b.csv:3: column 'time_s': recording 's2' steps by 0.2 s where "
               "recording 's1' ({root}/two_dts/a.csv) steps by 0.1 s: every file and "
               "recording must share one time step",
    "recording_in_two_files": "recording_in_two_files/b.csv:2: column 'recording': recording "
                              "'s1' is also in {root}/recording_in_two_files/a.csv (line 2): "
                              "a recording lies in one file (a file without a 'recording' "
                              "column is one recording named after the file)",
    "file_named_like_a_recording": "file_named_like_a_recording/s2.csv:2: column 'recording': "
                                   "recording 's1' is also in "
                                   "{root}/file_named_like_a_recording/s1.csv (line 2): a "
                                   "recording lies in one file (a file without a 'recording' "
                                   "column is one recording named after the file)",
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_logs_give_the_exact_file_line_column_message(tmp_path, name):
    path = _case(tmp_path, name)
    with pytest.raises(RecordingError) as err:
        read_logs(path)
    assert str(err.value) == f"{tmp_path}/" + MALFORMED[name].format(root=tmp_path)
    assert isinstance(err.value, ValueError)


def test_paths_that_hold_no_logs(tmp_path):
    with pytest.raises(RecordingError, match=r"^/\S+/nothing: no such file or folder$"):
        read_logs(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordingError, match=r"empty: no \.csv files in this folder$"):
        read_logs(tmp_path / "empty")


def test_a_bad_file_after_good_ones_returns_nothing(tmp_path):
    _write(tmp_path / "a.csv", HEADER, GOOD)
    _write(tmp_path / "b.csv", HEADER, [GOOD[0].replace("s1,bot,0.0,0.0", "s2,bot,0.0,x")])
    with pytest.raises(RecordingError, match=r"/b\.csv:2: column 'x_m': expected a number"):
        read_logs(tmp_path)


def test_quoted_values_excel_bom_and_crlf_are_read(tmp_path):
    rows = ['"s1","bot, the robot",0.0,0,0,1,0,robot', '"s1","bot, the robot",0.1,0.1,0,1,0,robot']
    path = tmp_path / "excel.csv"
    path.write_bytes(("\ufeff" + "\r\n".join([HEADER, *rows]) + "\r\n").encode("utf-8"))
    (rec,) = read_logs(path).recordings
    assert rec.tracks[0].name == "bot, the robot"


# ---------------------------------------------------------------- role-aware pairs


def test_robot_pairs_with_nearest_human_and_never_with_a_pedestrian(tmp_path):
    agents = {"bot": (0.0, "robot"), "walker": (0.5, "pedestrian"),  # nearest of all
              "near": (2.0, "human"), "far": (5.0, "human"), "rover": (9.0, "robot")}
    rows = [f"lab,{name},{f / 10:.1f},{0.8 * f / 10:.2f},{y},0.8,0,{role}"
            for f in range(20) for name, (y, role) in agents.items()]
    (rec,) = read_logs(_write(tmp_path / "room.csv", HEADER, rows)).recordings
    ids = {t.name: t.track_id for t in rec.tracks}
    found = px.pairs_in_window(rec, 0, 20, 8.0, rule=px.ROLES)
    assert {p.robot_id: p.human_id for p in found} == {ids["bot"]: ids["near"],
                                                       ids["rover"]: ids["far"]}
    np.testing.assert_allclose(found[0].positions[:, 1, 1] - found[0].positions[:, 0, 1], 2.0)
    assert [p.robot_id for p in px.pairs_in_window(rec, 0, 20, 1.0, rule=px.ROLES)] == []
    assert px.pairs_in_window(rec, 0, 20, 8.0) == []  # the default pairs cars only


def test_role_pairs_on_generated_logs_are_robot_then_human(logs):
    found = px.extract_pairs(logs.recordings, 20, 20, 4.0, rule=px.ROLES)
    assert len(found) > 10
    assert {(p.robot_id, p.human_id) for p in found} == {(1, 2)}
    assert {p.recording for p in found} == {r.name for r in logs.recordings}
    for pair in found:
        assert np.linalg.norm(pair.positions[:, 0] - pair.positions[:, 1], axis=-1).min() <= 4.0


def test_the_documented_example_reads_as_documented(tmp_path):
    page = Path(__file__).resolve().parents[2] / "docs" / "extend" / "robot-logs.md"
    section = page.read_text().split("# Your own robot logs (generic CSV)")[1]
    example = section.split("```csv\n")[1].split("```")[0]
    assert len(example.splitlines()) == 5
    (tmp_path / "hall.csv").write_text(example)
    logs = read_logs(tmp_path / "hall.csv")
    (rec,) = logs.recordings
    assert (rec.name, logs.dt_s) == ("hall_a", 0.1)
    tiago, p07 = rec.tracks
    assert (tiago.name, tiago.agent_type, p07.name, p07.agent_type) == ("tiago", "robot",
                                                                        "p07", "human")
    np.testing.assert_allclose(tiago.v, [[0.8, 0.0], [0.8, 0.0]])
    np.testing.assert_allclose(p07.v, [[-1.1, 0.05], [-1.1, 0.05]])
    assert np.isnan(p07.psi).all() and (tiago.psi == 0.0).all()


def test_the_generator_command_writes_logs_without_velocities(tmp_path, monkeypatch, capsys):
    from app.recordings import synthetic_logs

    out = tmp_path / "cli.csv"
    monkeypatch.setattr("sys.argv", ["synthetic_logs", str(out), "--recordings", "2",
                                     "--seconds", "5", "--seed", "4", "--no-velocities"])
    synthetic_logs.main()
    assert "NOT REAL DATA" in capsys.readouterr().out
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 2 * 51
    assert {(r["vx_mps"], r["vy_mps"]) for r in rows} == {("", "")}
    assert [r.name for r in read_logs(out).recordings] == ["generated_001", "generated_002"]


# ---------------------------------------------------------------- lines to draw


LINE_HEADER = "line_id,kind,dashed,x_m,y_m"
ROOM_LINES = [LINE_HEADER, "outer,wall,0,0,0", "outer,wall,false,12,0", "outer,wall,0,12,8",
              "lane,line_thin,1,6,0", "lane,line_thin,TRUE,6,8"]


def test_line_file_reads_lines_in_order_of_first_appearance(tmp_path):
    walls, lane = read_line_file(_write(tmp_path / "room.csv", ROOM_LINES[0], ROOM_LINES[1:]))
    assert (walls.kind, walls.subtype, lane.kind, lane.subtype) == ("wall", "solid",
                                                                    "line_thin", "dashed")
    np.testing.assert_array_equal(walls.points, [[0, 0], [12, 0], [12, 8]])
    np.testing.assert_array_equal(lane.points, [[6, 0], [6, 8]])


@pytest.mark.parametrize("rows, expected", [
    (["line_id,kind,x_m,y_m", "a,wall,0,0"], ":1: column 'dashed': missing from the header "
     "(expected line_id,kind,dashed,x_m,y_m)"),
    (["line_id,kind,x_m,dashed,y_m", "a,wall,0,0,0"], ":1: column 'x_m': found as column 3 "
     "where 'dashed' is expected (expected line_id,kind,dashed,x_m,y_m, in this order)"),
    ([LINE_HEADER, "a,kerb,0,0,0"], ":2: column 'kind': 'kerb' is not a line kind: expected "
     "one of curbstone, road_border, guard_rail, fence, wall, line_thin, line_thick, virtual, "
     "pedestrian_marking, zebra_marking, stop_line"),
    ([LINE_HEADER, "a,wall,yes,0,0"], ":2: column 'dashed': expected 1, 0, true or false, "
     "found 'yes'"),
    ([LINE_HEADER, "a,wall,0,0,0", "a,wall,1,1,0"], ":3: column 'dashed': line 'a' is '1' "
     "here but not at line 2: one kind and style per line"),
    ([LINE_HEADER, "a,wall,0,0,0", "a,wall,0,1,0", "b,wall,0,3,3"], ":4: column 'line_id': "
     "line 'b' has one point: a line needs two or more"),
    ([LINE_HEADER, "a,wall,0,inf,0"], ":2: column 'x_m': 'inf' is not finite: expected a "
     "number"),
])
def test_malformed_line_file_gives_the_exact_message(tmp_path, rows, expected):
    path = _write(tmp_path / "lines.csv", rows[0], rows[1:])
    with pytest.raises(RecordingError) as err:
        read_line_file(path)
    assert str(err.value) == f"{path}{expected}"


# ---------------------------------------------------------------- a recorded world of lab logs


def test_generated_lab_logs_import_as_a_recorded_world(tmp_path):
    from app.data.trajectory import TrajectorySet
    from app.layout import Layout
    from app.recordings.config import RecordedConfig
    from app.recordings.importer import import_recordings

    logs = tmp_path / "recordings" / "lab" / "logs.csv"
    generate_logs(logs, recordings=4, seconds=60.0, seed=0)
    _write(logs.parent / "room_lines.csv", ROOM_LINES[0], ROOM_LINES[1:])
    config = RecordedConfig.model_validate({
        "kind": "recorded", "pair_max_distance_m": 10.0,
        "agent": {"kind": "disc", "length_m": 0.6, "width_m": 0.6},
        "source": {"format": "csv", "path": "lab/logs.csv", "lines": "lab/room_lines.csv"}})
    layout = Layout(tmp_path / "var", tmp_path / "recordings")
    meta = import_recordings("lab", config, layout).meta
    assert set(meta["input_sha256"]) == {"logs.csv", "room_lines.csv"}
    assert (meta["frame_dt_s"], meta["pairs"]) == (0.1, {"train": 45, "held_out": 15})
    assert meta["recordings"] == {"train": 3, "val": 1}  # one of four recordings held out
    trajs = TrajectorySet.load(layout.trajectories("lab"))
    assert trajs.positions.shape == (60, 10, 2, 2)  # 4 s windows (40 frames), every 4th frame
    speeds = trajs.speeds[:, :, 0]  # the robot (0.8 m/s) is agent 0, the person (1.2) agent 1
    assert speeds.max() <= 0.8 + 0.002 < trajs.speeds[:, :, 1].max()
    assert [(line.kind, line.dashed) for line in trajs.scene.recorded.lines] == [
        ("kerb", False), ("border", True)]
