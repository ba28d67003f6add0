"""INTERACTION loader: both layouts, every malformed-file error, pairs, maps, the generator."""

import csv
from pathlib import Path

import numpy as np
import pytest

from app.recordings import pairs as px
from app.recordings import synthetic_tracks as syn
from app.recordings import tracks as ix
from app.recordings.lanelet_map import OriginProjector, read_lanelet_map
from app.recordings.synthetic_tracks import generate, lane_lines, read_manoeuvre_labels

HEADER = ",".join(ix.VEHICLE_COLUMNS)


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _car_rows(track: int, frames: range, x0: float, y0: float, vx: float) -> list[str]:
    return [f"{track},{f},{f * 100},car,{x0 + vx * 0.1 * f:.3f},{y0:.3f},{vx},0.0,0.0,4.5,1.8"
            for f in frames]


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("interaction")
    for layout in ("v1.2", "v1.0"):
        for scenario in ("DR_USA_Roundabout_FT", "DR_USA_Intersection_EP0"):
            generate(root / layout, scenario, layout, train_s=40.0, val_s=20.0, seed=3)
    return root


# ---------------------------------------------------------------- malformed files


def _malformed(tmp_path: Path, name: str) -> tuple[Path, str]:
    good = _car_rows(1, range(1, 4), 0, 0, 5)
    bodies = {
        "missing_column": (HEADER.replace(",vy", ""), [r.rsplit(",", 4)[0] + ",0.0,4.5,1.8"
                                                       for r in good]),
        "reordered_columns": (HEADER.replace("x,y", "y,x"), good),
        "non_numeric_x": (HEADER, [good[0], good[1].replace(",car,1.000", ",car,abc"), good[2]]),
        "off_grid_timestamp": (HEADER, [good[0], good[1].replace(",200,", ",250,"), good[2]]),
        "empty_file": ("", []),
    }
    header, rows = bodies[name]
    text = "\n".join([header, *rows]) + ("\n" if header else "")
    return _write(tmp_path / f"{name}.csv", text), name


@pytest.mark.parametrize("name, expected", [
    ("missing_column", ":1: header is missing column 'vy'"),
    ("reordered_columns", ":1: column 5 is 'y' where 'x' is expected"),
    ("non_numeric_x", ":3: column 'x': expected a number, found 'abc"),
    ("off_grid_timestamp", ":3: column 'timestamp_ms': 250 is not on the 100 ms grid"),
    ("empty_file", ":1: empty file"),
])
def test_malformed_file_errors_name_file_line_and_column(tmp_path, name, expected):
    path, _ = _malformed(tmp_path, name)
    with pytest.raises(ix.TrackFileError) as err:
        ix.read_track_file(path)
    message = str(err.value)
    assert message.startswith(str(path))
    assert expected in message
    assert "\n" not in message


def test_malformed_file_through_the_command_is_a_clean_error(tmp_path):
    from typer.testing import CliRunner

    from app.cli import cli

    folder = tmp_path / "recorded_trackfiles" / "DR_USA_Roundabout_FT"
    bad, _ = _malformed(folder, "non_numeric_x")
    bad.rename(folder / "vehicle_tracks_000.csv")
    result = CliRunner().invoke(cli, ["interaction", "--data", str(tmp_path), "--scenario",
                                      "DR_USA_Roundabout_FT"])
    assert result.exit_code == 2
    assert "vehicle_tracks_000.csv:3: column 'x'" in result.output
    assert "Traceback" not in result.output


def test_wrong_field_count_header_only_and_missing_scenario(tmp_path):
    short = _write(tmp_path / "short.csv", HEADER + "\n1,1,100,car,1.0\n")
    with pytest.raises(ix.TrackFileError, match=r"short.csv:2: expected 11 fields, found 5"):
        ix.read_track_file(short)
    header_only = _write(tmp_path / "header.csv", HEADER + "\n")
    with pytest.raises(ix.TrackFileError, match=r"header.csv:2: no data rows"):
        ix.read_track_file(header_only)
    with pytest.raises(ix.TrackFileError, match="no tracks for scenario 'DR_X'"):
        ix.detect_layout(tmp_path, "DR_X")


def test_car_without_length_is_an_error_but_pedestrian_is_not(tmp_path):
    rows = ["1,1,100,pedestrian/bicycle,1.0,2.0,1.0,0.0,,,",
            "2,1,100,car,1.0,2.0,1.0,0.0,0.0,,1.8"]
    path = _write(tmp_path / "mixed.csv", "\n".join([HEADER, *rows]) + "\n")
    with pytest.raises(ix.TrackFileError, match=r"mixed.csv:3: column 'length'"):
        ix.read_track_file(path)
    ok = _write(tmp_path / "ped.csv", "\n".join([HEADER, rows[0]]) + "\n")
    (rec,) = ix.read_track_file(ok)
    assert rec.tracks[0].agent_type == "pedestrian/bicycle"
    assert not rec.tracks[0].is_car


# ---------------------------------------------------------------- both layouts


def test_v12_cases_and_test_columns(tmp_path):
    header = ",".join([*ix.CASE_COLUMNS, *ix.OPTIONAL_TRAILING])
    rows = [f"{case}.0,{r},1,1" for case in (1, 2) for r in _car_rows(1, range(1, 41), 0, 0, 8)]
    path = _write(tmp_path / "test.csv", "\n".join([header, *rows]) + "\n")
    recordings = ix.read_track_file(path)
    assert [r.name for r in recordings] == ["test#case1", "test#case2"]
    track = recordings[0].tracks[0]
    assert track.frames.tolist() == list(range(1, 41))
    np.testing.assert_allclose(track.v[:, 0], 8.0)
    assert track.length_m == pytest.approx(4.5)


def test_both_generated_layouts_load_with_pedestrians_kept_out_of_pairs(generated):
    for layout in ("v1.2", "v1.0"):
        data = generated / layout
        assert ix.detect_layout(data, "DR_USA_Roundabout_FT") == layout
        files = ix.split_files(data, "DR_USA_Roundabout_FT", layout)
        recordings = ix.load_recordings(files["train"])
        kinds = {k for r in recordings for k in r.counts()}
        assert kinds == {"car", "pedestrian/bicycle"}
        pairs = px.extract_pairs(recordings, 40, 40, 30.0)
        assert len(pairs) > 20
        walkers = {(r.name, t.track_id) for r in recordings for t in r.tracks if not t.is_car}
        for pair in pairs:
            assert (pair.recording, pair.robot_id) not in walkers
            assert (pair.recording, pair.human_id) not in walkers
            assert pair.positions.shape == (40, 2, 2)


def test_pair_rule_picks_nearest_car_present_over_the_whole_window(tmp_path):
    rows = (_car_rows(1, range(1, 41), 0, 0, 8)         # robot candidate
            + _car_rows(2, range(1, 41), 0, 10, 8)      # 10 m to the side all along
            + _car_rows(3, range(1, 41), 0, 4, 8)[:30]  # nearer, but leaves the window early
            + _car_rows(4, range(1, 41), 0, 80, 8))     # present but 80 m away
    rows.append("9,5,500,pedestrian/bicycle,1.0,1.0,1.0,0.0,,,")  # right on top: never paired
    path = _write(tmp_path / "vehicle_tracks_000.csv", "\n".join([HEADER, *rows]) + "\n")
    (rec,) = ix.read_track_file(path)
    pairs = {p.robot_id: p.human_id for p in px.pairs_in_window(rec, 1, 40, 30.0)}
    assert pairs == {1: 2, 2: 1}  # car 3 is not present throughout, car 4 is beyond 30 m
    pair = px.pairs_in_window(rec, 1, 40, 30.0)[0]
    np.testing.assert_allclose(pair.positions[:, 1, 1] - pair.positions[:, 0, 1], 10.0)
    np.testing.assert_allclose(pair.speeds, 8.0)


def test_v10_time_split_keeps_windows_apart(generated):
    data = generated / "v1.0"
    recordings = ix.load_recordings(ix.split_files(data, "DR_USA_Intersection_EP0", "v1.0")
                                    ["train"])
    ranges = px.time_split(recordings, 0.8)
    train = px.extract_pairs(recordings, 40, 40, 30.0, ranges["train"])
    val = px.extract_pairs(recordings, 40, 40, 30.0, ranges["val"])
    assert train and val
    for pair in val:
        assert pair.first_frame >= ranges["val"][pair.recording][0]
    for pair in train:
        assert pair.first_frame + 39 <= ranges["train"][pair.recording][1]


def test_generator_labels_cover_every_car_row(generated):
    data = generated / "v1.2"
    labels = read_manoeuvre_labels(data / "generator_labels" / "DR_USA_Intersection_EP0_train.csv")
    assert {row["turn"] for row in labels.values()} == {"straight", "left", "right"}
    assert all(set(row) == {"entry_arm", "exit_arm", "turn"} for row in labels.values())
    with open(data / "train" / "DR_USA_Intersection_EP0_train.csv") as fh:
        cars = [r for r in csv.DictReader(fh) if r["agent_type"] == "car"]
    assert len(cars) == len(labels)
    round_labels = read_manoeuvre_labels(data / "generator_labels" /
                                      "DR_USA_Roundabout_FT_train.csv")
    assert {row["phase"] for row in round_labels.values()} == {"enter", "circle", "exit"}
    # a car's route labels stay the same over its whole track
    routes: dict = {}
    for (recording, track, _), row in round_labels.items():
        routes.setdefault((recording, track), set()).add((row["entry_arm"], row["exit_arm"],
                                                          row["turn"]))
    assert all(len(r) == 1 for r in routes.values())


@pytest.mark.parametrize("kind", ["roundabout", "intersection"])
def test_turn_label_matches_the_route_geometry(kind):
    """left / right is the sign of the heading change from entry to exit (y up); the exit
    arm is where the route ends."""
    for arm in range(4):
        for option in ((1, 2, 3) if kind == "roundabout" else (0, 1, 2)):
            route = (syn.roundabout_route(arm, option) if kind == "roundabout"
                     else syn.intersection_route(arm, option))
            moves = np.diff(route.points, axis=0)
            turn = np.degrees(np.unwrap(np.arctan2(moves[:, 1], moves[:, 0])))
            change = (turn[-1] - turn[0] + 180) % 360 - 180
            expected = "left" if change > 45 else "right" if change < -45 else "straight"
            assert route.turn == expected
            end_angle = np.arctan2(route.points[-1, 1], route.points[-1, 0])
            off = (end_angle - syn.ARM_ANGLES[route.exit_arm] + np.pi) % (2 * np.pi) - np.pi
            assert abs(off) < 0.1


# ---------------------------------------------------------------- maps


def test_utm_projection_matches_known_values():
    projector = OriginProjector()  # zone 31; (0, 0) is 166021.443 m east of the false origin
    assert projector.zone == 31 and projector.x0 == pytest.approx(166021.443, abs=0.01)
    # on the central meridian: easting 500 km, northing k0 * meridian arc
    np.testing.assert_allclose(projector.to_xy([45.0], [3.0]),
                               [[500000.0 - 166021.443, 4982950.400]], atol=0.01)


def test_generated_map_round_trips_through_lat_lon(generated):
    lines = read_lanelet_map(generated / "v1.2" / "maps" / "DR_USA_Roundabout_FT.osm",
                             OriginProjector())
    expected = lane_lines("roundabout")
    assert len(lines) == len(expected)
    for got, (kind, subtype, points) in zip(lines, expected, strict=True):
        assert (got.kind, got.subtype) == (kind, subtype)
        np.testing.assert_allclose(got.points, points + 1000.0, atol=1e-3)


def test_unreadable_map_is_a_clear_error(tmp_path):
    from app.recordings.lanelet_map import MapError

    bad = _write(tmp_path / "m.osm", "<osm><node id='1' lat='x' lon='0'/></osm>")
    with pytest.raises(MapError, match="node 1 lacks a numeric lat/lon"):
        read_lanelet_map(bad)


def test_duplicate_frame_in_a_track_names_the_line(tmp_path):
    rows = _car_rows(1, range(1, 4), 0, 0, 5)
    path = _write(tmp_path / "dup.csv", "\n".join([HEADER, *rows, rows[1]]) + "\n")
    with pytest.raises(ix.TrackFileError, match=r"dup.csv:5: column 'timestamp_ms': track 1 "
                                                r"has two rows at 200 ms"):
        ix.read_track_file(path)


def test_v12_file_without_case_id_is_a_missing_column(tmp_path):
    rows = _car_rows(1, range(1, 4), 0, 0, 5)
    path = _write(tmp_path / "train" / "DR_X_train.csv", "\n".join([HEADER, *rows]) + "\n")
    with pytest.raises(ix.TrackFileError, match=r"DR_X_train.csv:1: header is missing column "
                                                r"'case_id'"):
        ix.read_track_file(path)


def test_v10_official_validation_list_splits_whole_recordings(generated, tmp_path):
    import shutil

    data = tmp_path / "v1.0"
    shutil.copytree(generated / "v1.0" / "recorded_trackfiles", data / "recorded_trackfiles")
    (data / "recorded_trackfiles" / ix.OFFICIAL_VAL_LIST).write_text(
        "DR_OTHER \nvehicle_tracks_000\n\nDR_USA_Intersection_EP0 \nvehicle_tracks_001\n")
    names = ix.official_val_recordings(data, "DR_USA_Intersection_EP0")
    assert names == ["vehicle_tracks_001"]
    recordings = ix.load_recordings(ix.split_files(data, "DR_USA_Intersection_EP0", "v1.0")
                                    ["train"])
    ranges = px.recording_split(recordings, names)
    val = px.extract_pairs(recordings, 40, 40, 30.0, ranges["val"])
    train = px.extract_pairs(recordings, 40, 40, 30.0, ranges["train"])
    assert {p.recording for p in val} == {"vehicle_tracks_001"}
    assert {p.recording for p in train} == {"vehicle_tracks_000"}


def test_projection_matches_the_devkit_convention(tmp_path):
    # nodes of the devkit's public test map, whose track file drives along y = 2.5 and 5.5
    # between lane lines at y = 1, 4 and 7 m
    osm = _write(tmp_path / "t.osm", """<?xml version="1.0"?><osm version="0.6">
      <node id="1" lat="0.00000903483" lon="0.00000897435"/>
      <node id="2" lat="0.00000903484" lon="0.00090640957"/>
      <node id="3" lat="0.00003613932" lon="0.00000897435"/>
      <node id="4" lat="0.00006324382" lon="0.00000897435"/>
      <way id="10"><nd ref="1"/><nd ref="2"/><tag k="type" v="road_border"/></way>
      <way id="11"><nd ref="3"/><nd ref="4"/><tag k="type" v="line_thin"/>
        <tag k="subtype" v="dashed"/></way></osm>""")
    border, thin = read_lanelet_map(osm, OriginProjector())
    np.testing.assert_allclose(border.points, [[1, 1], [101, 1]], atol=1e-3)
    np.testing.assert_allclose(thin.points, [[1, 4], [1, 7]], atol=1e-3)
    assert (thin.kind, thin.subtype) == ("line_thin", "dashed")


def _checked_rows(path: Path) -> "ix._Columns":
    with ix.csv_reader(path) as reader:
        columns = ix._check_header(path, [c.strip() for c in next(reader)])
        return ix._parse_rows(path, reader, columns), columns


@pytest.mark.parametrize("layout, name", [("v1.2", "train/DR_USA_Roundabout_FT_train.csv"),
                                          ("v1.0", "recorded_trackfiles/DR_USA_Intersection_EP0/"
                                                   "vehicle_tracks_000.csv"),
                                          ("v1.0", "recorded_trackfiles/DR_USA_Intersection_EP0/"
                                                   "pedestrian_tracks_000.csv")])
def test_the_vectorised_reader_reads_what_the_checking_reader_reads(generated, tmp_path, layout,
                                                                    name):
    lines = (generated / layout / name).read_text().split("\n")
    lines.insert(3, "   ")  # a blank line still counts for the line numbers
    path = _write(tmp_path / Path(name).name, "\n".join(lines))
    checked, columns = _checked_rows(path)
    plain = ix._plain_rows(path, columns)
    assert plain is not None and len(plain) == len(checked) > 0
    assert bytes(plain.ids) == bytes(checked.ids)  # case, track, frame, line
    assert bytes(plain.values) == bytes(checked.values)  # bit for bit, NaN sizes included
    assert plain.types == checked.types


def test_the_vectorised_reader_leaves_a_doubtful_file_to_the_checking_reader(tmp_path):
    good = _car_rows(1, range(1, 4), 0, 0, 5)
    for rows in ([good[0], good[1].replace(",car,", ',"car",')], [good[0], good[1] + ",1"],
                 [good[0], good[1].replace(",200,", ",250,")], [good[0] + "\r"]):
        path = _write(tmp_path / "doubt.csv", "\n".join([HEADER, *rows]) + "\n")
        assert ix._plain_rows(path, ix.VEHICLE_COLUMNS) is None


def test_real_size_files_are_v10_recordings_at_the_asked_density(tmp_path):
    from app.recordings.generated import generate_study_recordings

    sparse, dense = (generate_study_recordings(tmp_path / name, 60.0, files=2,
                                               arrivals_per_arm_min=rate)
                     for name, rate in (("sparse", 6.0), ("dense", 24.0)))
    for scenario in ("DR_USA_Roundabout_FT", "DR_USA_Intersection_EP0"):
        folder = tmp_path / "dense" / "recorded_trackfiles" / scenario
        assert sorted(p.name for p in folder.glob("vehicle_tracks_*.csv")) == [
            "vehicle_tracks_000.csv", "vehicle_tracks_001.csv"]
        assert (tmp_path / "dense" / "generator_labels" /
                f"{scenario}_vehicle_tracks_001.csv").is_file()
    assert all(d["cars"] > s["cars"] for d, s in zip(dense, sparse, strict=True))
    with pytest.raises(ValueError, match="arrivals per arm per minute: 60 is not in"):
        generate(tmp_path / "x", "DR_USA_Roundabout_FT", "v1.0", 60.0, 30.0,
                 arrivals_per_arm_min=60.0)
