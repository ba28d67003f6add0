"""A partial v1.0 download: a devkit validation list naming recordings the copy lacks is a clear
error naming them and what to do, from every command that reads the list."""

from pathlib import Path

import pytest
from typer.testing import CliRunner

from app.cli import cli
from app.interaction.config import InteractionConfig
from app.layout import Layout
from app.recordings import tracks as tx
from app.recordings.config import RecordedConfig
from app.recordings.importer import import_recordings
from app.recordings.synthetic_tracks import generate
from app.settings import get_settings
from tests.recordings.scenarios import INTERSECTION, ROUNDABOUT, recorded_config

ABSENT = "vehicle_tracks_007"


@pytest.fixture(scope="module")
def partial(tmp_path_factory) -> Path:
    """GENERATED v1.0 files of both study scenarios (recordings 000 and 001 each) and a
    validation list holding out the roundabout's 001 and a 007 that is not in the copy."""
    root = tmp_path_factory.mktemp("recordings")
    data = root / "INTERACTION"
    for seed, scenario in enumerate((ROUNDABOUT, INTERSECTION)):
        generate(data, scenario, "v1.0", train_s=60.0, val_s=60.0, seed=seed)
    (data / "recorded_trackfiles" / tx.OFFICIAL_VAL_LIST).write_text(
        f"{ROUNDABOUT}\nvehicle_tracks_001\n{ABSENT}\n")
    return root


def assert_names_the_absent_file(message: str) -> None:
    assert f"{tx.OFFICIAL_VAL_LIST}: 1 of the 2 {ROUNDABOUT} recordings" in message
    assert (f"{Path('recorded_trackfiles') / ROUNDABOUT}: {ABSENT} (2 recordings are there: "
            "a partial download?)") in message
    assert "Add the missing files; or remove the list" in message


@pytest.fixture
def env(partial, tmp_path, monkeypatch):
    """The CLI's settings: this test's data dir, the partial copy as the recordings dir."""
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(tmp_path / "var"))
    monkeypatch.setenv("TOMSTUDY_RECORDINGS_DIR", str(partial))
    get_settings.cache_clear()
    yield tmp_path / "var"
    get_settings.cache_clear()


@pytest.mark.parametrize("args, switch", [
    (["import-recordings", "roundabout"], "source.validation_list: ignore"),
    (["bundle", "build", "--study", "interaction_study"], "source.validation_list: ignore"),
    (["interaction", "--data", "{data}", "--scenario", ROUNDABOUT],
     "v10_validation_list: ignore"),
])
def test_each_command_names_the_absent_files_and_what_to_do(env, partial, args, switch):
    args = [a.format(data=partial / "INTERACTION") for a in args]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert_names_the_absent_file(result.output)
    assert switch in result.output.replace("\n", " ")
    assert not (env / "data" / "roundabout" / "trajectories.npz").exists()


def test_the_switch_holds_out_each_recordings_end_and_is_left_out_at_its_default(partial,
                                                                                 tmp_path):
    ignoring = recorded_config(ROUNDABOUT).model_dump()
    ignoring["source"]["validation_list"] = "ignore"
    result = import_recordings("roundabout", RecordedConfig.model_validate(ignoring),
                               Layout(tmp_path, partial))
    assert result.meta["recordings"] == {"train": 2, "val": 2}  # both split in time
    assert result.meta["config"]["source"]["validation_list"] == "ignore"
    assert "validation_list" not in recorded_config(ROUNDABOUT).model_dump()["source"]
    assert "v10_validation_list" not in InteractionConfig().model_dump()
    assert InteractionConfig(v10_validation_list="ignore").model_dump()[
        "v10_validation_list"] == "ignore"


def test_a_complete_copy_keeps_the_lists_split(partial, tmp_path):
    complete = tmp_path / "INTERACTION"
    (complete / "recorded_trackfiles").mkdir(parents=True)
    (complete / "recorded_trackfiles" / ROUNDABOUT).symlink_to(
        partial / "INTERACTION" / "recorded_trackfiles" / ROUNDABOUT)
    (complete / "recorded_trackfiles" / tx.OFFICIAL_VAL_LIST).write_text(
        f"{ROUNDABOUT}\nvehicle_tracks_001\n")
    result = import_recordings("roundabout", recorded_config(ROUNDABOUT), Layout(tmp_path / "var",
                                                                          tmp_path))
    assert result.meta["recordings"] == {"train": 1, "val": 1}  # whole recordings
