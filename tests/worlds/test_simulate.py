"""The `tomstudy simulate` driver on the (fast) obstacle world: errors, atomic output, meta.json,
reproducibility."""

import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from app.cli import cli
from app.core.files import sha256_file
from app.settings import REPO_ROOT, get_settings
from tests.conftest import TOMSTUDY, patience

CONFIG = REPO_ROOT / "study_configs" / "worlds" / "obstacle.yaml"


@pytest.fixture
def data_dir(tmp_path, monkeypatch) -> Path:
    """TOMSTUDY_DATA_DIR pointed at a fresh folder for this test."""
    folder = tmp_path / "var"
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(folder))
    get_settings.cache_clear()
    yield folder
    get_settings.cache_clear()


def run_cli(*args: str):
    return CliRunner().invoke(cli, ["simulate", *args])


def edited_config(path: Path, edit) -> Path:
    data = yaml.safe_load(CONFIG.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data))
    return path


def outputs(data_dir: Path) -> tuple[Path, Path]:
    folder = data_dir / "data" / "obstacle"
    return folder / "trajectories.npz", folder / "meta.json"


def leftover_files(data_dir: Path) -> list[str]:
    """Anything in the output folder: final files or temporary ones."""
    folder = outputs(data_dir)[0].parent
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def test_misspelt_yaml_key_exits_2_naming_the_field(data_dir, tmp_path):
    def misspell(data):
        data["reward"]["goal_bonnus"] = data["reward"].pop("goal_bonus")

    result = run_cli("obstacle", "--n", "2", "--config",
                     str(edited_config(tmp_path / "bad.yaml", misspell)))
    assert result.exit_code == 2
    assert "reward.goal_bonnus" in result.output
    assert not outputs(data_dir)[0].exists()


def test_negative_n_exits_2_naming_the_option(data_dir):
    result = run_cli("obstacle", "--n", "-5")
    assert result.exit_code == 2
    assert "--n" in result.output


def test_unknown_world_exits_2(data_dir):
    result = run_cli("moon", "--n", "2")
    assert result.exit_code == 2
    assert "world" in result.output and "moon" in result.output


def test_missing_config_file_exits_2(data_dir, tmp_path):
    missing = tmp_path / "nowhere.yaml"
    result = run_cli("obstacle", "--n", "2", "--config", str(missing))
    assert result.exit_code == 2
    assert "nowhere.yaml" in result.output and "not found" in result.output


def test_failed_run_leaves_no_output(data_dir, tmp_path):
    def impossible(data):
        data["max_steps"] = 2  # no robot can reach its goal in two steps: all rejected

    config = edited_config(tmp_path / "short.yaml", impossible)
    result = run_cli("obstacle", "--n", "1", "--workers", "1", "--config", str(config))
    assert result.exit_code != 0
    assert "rejected" in str(result.exception)
    assert leftover_files(data_dir) == []


@pytest.mark.slow
def test_interrupted_run_leaves_no_trajectories(data_dir, tmp_path):
    env = dict(os.environ, TOMSTUDY_DATA_DIR=str(data_dir))
    log = tmp_path / "stderr.log"
    with open(log, "wb") as err:  # a file, not a pipe: a full pipe would block the child
        proc = subprocess.Popen([TOMSTUDY, "simulate", "obstacle", "--n", "2000"],
                                env=env, stdout=subprocess.DEVNULL, stderr=err, cwd=REPO_ROOT,
                                preexec_fn=_hear_ctrl_c)
    try:
        _wait_for_progress(proc, log)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=patience(60))
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode != 0
    assert leftover_files(data_dir) == []


def _hear_ctrl_c() -> None:
    """Let the child hear SIGINT even when the suite runs as a background job."""
    # a shell without job control starts `cmd &` with SIGINT ignored, and a Python started
    # with it ignored never raises KeyboardInterrupt: the run would finish instead of stopping
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _wait_for_progress(proc: subprocess.Popen, log: Path, timeout_s: float = 120) -> None:
    """Block until the progress bar counts finished trajectories (the pool is running)."""
    deadline = time.monotonic() + patience(timeout_s)
    while time.monotonic() < deadline:
        done = [int(k) for k in re.findall(r"(\d+)/2000", log.read_text(errors="replace"))]
        if done and max(done) > 0:
            return
        assert proc.poll() is None, log.read_text(errors="replace")
        time.sleep(0.1)
    raise AssertionError("simulation never started")


def test_meta_json_records_the_run(data_dir):
    result = run_cli("obstacle", "--n", "6", "--seed", "3", "--workers", "2")
    assert result.exit_code == 0, result.output
    npz, meta_path = outputs(data_dir)
    meta = json.loads(meta_path.read_text())
    for key in ("config", "seed", "dt_s", "label_counts", "rejected", "wall_time_s",
                "package_version", "content_sha256"):
        assert key in meta, key
    assert meta["seed"] == 3 and meta["n"] == 6 and meta["dt_s"] == 0.5
    assert meta["config"]["max_speed_mps"] == yaml.safe_load(CONFIG.read_text())["max_speed_mps"]
    assert sum(meta["label_counts"]["robot_goal"].values()) == 6
    assert meta["attempts"] == 6 + sum(meta["rejected"].values())
    assert meta["wall_time_s"] > 0
    assert meta["content_sha256"] == sha256_file(npz)


def test_same_seed_same_bytes_whatever_the_worker_count(tmp_path, monkeypatch):
    digests = []
    for name, seed, workers in (("a", 5, "1"), ("b", 5, "2"), ("c", 6, "2")):
        monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(tmp_path / name))
        get_settings.cache_clear()
        result = run_cli("obstacle", "--n", "6", "--seed", str(seed), "--workers", workers)
        assert result.exit_code == 0, result.output
        digests.append(sha256_file(outputs(tmp_path / name)[0]))
    get_settings.cache_clear()
    assert digests[0] == digests[1]
    assert digests[0] != digests[2]
