"""The human-relative frame: exact and invertible, and its sensitivity row in summary.json."""

import json

import numpy as np
import pytest

from app.data.trajectory import HUMAN, ROBOT
from app.data.windows import Windows
from app.interaction import config as ic
from app.interaction import frames
from app.layout import Layout
from app.recordings.synthetic_tracks import generate

SCENARIO = "DR_USA_Intersection_EP0"


def hand_made_pair() -> np.ndarray:
    """One window [1, 4 steps, 2 agents, 2]: robot drives east, human north (exact values)."""
    robot = np.array([[10.0, 2.0], [11.5, 2.0], [13.0, 2.0], [14.5, 2.25]])
    human = np.array([[20.0, -4.0], [20.0, -3.0], [20.0, -2.0], [20.25, -1.0]])
    return np.stack([robot, human], axis=1)[None]


def test_human_relative_transform_is_exact_and_invertible():
    positions = hand_made_pair()
    origin = frames.human_origin(positions, anchor_step=2)
    np.testing.assert_array_equal(origin, [[20.0, -2.0]])
    relative = frames.to_human_relative(positions, origin)
    np.testing.assert_array_equal(relative[0, 2, HUMAN], [0.0, 0.0])  # the human is the origin
    np.testing.assert_array_equal(relative[0, :, ROBOT],
                                  [[-10.0, 4.0], [-8.5, 4.0], [-7.0, 4.0], [-5.5, 4.25]])
    np.testing.assert_array_equal(frames.from_human_relative(relative, origin), positions)
    # a translation: every velocity (position difference) is the same in both frames
    np.testing.assert_array_equal(np.diff(relative, axis=1), np.diff(positions, axis=1))


def test_windows_move_to_the_human_at_the_last_observed_step():
    positions = np.repeat(hand_made_pair(), 2, axis=0).astype(np.float32)
    positions[1] += 100.0  # a second window elsewhere on the map sees the same
    windows = Windows(positions, np.zeros(2, np.int64), np.zeros(2, np.int64), segment_len=2,
                      n_actions=1, dt_s=0.5, labels={})
    moved = frames.in_frame(windows, "human_relative")
    np.testing.assert_array_equal(moved.end_states[:, HUMAN], 0.0)
    np.testing.assert_array_equal(moved.positions[0], moved.positions[1])
    np.testing.assert_array_equal(moved.pred_targets, windows.pred_targets)
    assert frames.in_frame(windows, "absolute") is windows
    with pytest.raises(ValueError, match="unknown frame"):
        frames.in_frame(windows, "robot_relative")


def test_frame_row_config_is_pre_specified_and_overridable():
    cfg = ic.load_config(None, None)
    assert cfg.frame_sensitivity.frame == "human_relative" and cfg.frame_sensitivity.seeds == 5
    assert ic.load_config(None, None, frame_seeds=0).frame_sensitivity.seeds == 0
    with pytest.raises(ValueError, match="at least 2"):
        ic.load_config(None, None, frame_seeds=1)


def test_sensitivity_row_appears_in_summary_and_report(tmp_path):
    from app.interaction.experiment import run_command
    from app.interaction.report import frame_verdict

    data = tmp_path / "data"
    generate(data, SCENARIO, "v1.2", train_s=60.0, val_s=24.0, seed=5)
    config = tmp_path / "interaction.yaml"  # one levels cell: the row, not the grid, is tested
    config.write_text("code_levels:\n  levels: [[3, 3]]\n")
    summary = run_command(data, SCENARIO, Layout(tmp_path / "var"), config=config, seeds=2,
                          max_epochs=2, frame_seeds=2, out_dir=tmp_path / "out")
    primary = summary["paper_protocol"]
    row = summary["sensitivity"]["human_relative_frame"]
    assert row["frame"] == "human_relative" and row["seeds"] == 2
    assert set(row) == set(primary) | {"frame", "seeds"}
    assert set(row["tests"]) == set(primary["tests"])
    assert row["val_windows_scored"] == primary["val_windows_scored"]
    assert row["mean_alignment_error"]["cv"] == primary["mean_alignment_error"]["cv"]
    assert all(len(v) == 2 for v in row["per_seed_alignment_error"].values())
    written = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert written["sensitivity"]["human_relative_frame"]["seeds"] == 2
    html = (tmp_path / "out" / "report.html").read_text()
    assert "other car&#39;s point of view" in html or "other car's point of view" in html
    assert frame_verdict(summary).startswith("Human-relative frame (2 seeds): Ours ")
    assert frame_verdict({"paper_protocol": primary}) is None
    models = tmp_path / "var" / "models" / "interaction" / SCENARIO / "human_relative"
    assert (models / "seed_1" / "vae" / "checkpoint.pt").is_file()
