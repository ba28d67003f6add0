"""A recorded world's typed config (study_configs/worlds/<world>.yaml with `kind: recorded`).

A recorded world is read from recordings instead of simulated: the INTERACTION dataset's
track files (v1.0 or v1.2 layout, app/recordings/tracks.py) or a lab's own CSV logs
(app/recordings/csv_logs.py). `source.path` is relative to the recordings dir
(TOMSTUDY_RECORDINGS_DIR, default <data dir>/recordings): the lab's licensed download or its
own logs stay on its machine and never enter git.
"""

from typing import Annotated, Literal

from pydantic import Field, model_validator

from app.configio import StrictModel, omitted_when_default

MIN_WINDOW_STEPS = 9


class InteractionSource(StrictModel):
    """INTERACTION track files of one scenario, in the devkit's v1.0 or v1.2 layout.

    Held out (the bank's trials, never trained on): v1.2's val file; v1.0's recordings the
    devkit's validation list names (unless `validation_list: ignore`), else the last
    `held_out_fraction` of each recording."""

    format: Literal["interaction"] = Field(description="`interaction`: the INTERACTION "
                                           "dataset's track files")
    path: str = Field(min_length=1, description="the download's folder, relative to the "
                      "recordings dir (or absolute)")
    scenario: str = Field(min_length=1, description="e.g. DR_USA_Roundabout_FT")
    held_out_fraction: float = Field(0.2, gt=0, lt=1, description="v1.0 without the "
                                     "validation list: the last this share (0-1) of each "
                                     "recording, in time, is held out")
    validation_list: Literal["use", "ignore"] = Field(
        "use", description="v1.0: hold out the devkit's validation list's recordings, or "
        "ignore the list (a partial download) and hold out each recording's last part")
    _without_new_keys = omitted_when_default("validation_list")


class CsvSource(StrictModel):
    """A lab's own logs in the generic CSV format (one file or a folder of them).

    Held out: an evenly spaced `held_out_fraction` of the recordings (sorted by name); a
    single recording is split in time instead (its last `held_out_fraction`). `lines` is an
    optional CSV of lines to draw under the agents (line_id, kind, dashed, x_m, y_m), relative
    to the recordings dir like `path` (not inside a folder of logs: each .csv there is a log)."""

    format: Literal["csv"] = Field(description="`csv`: the generic robot-log CSV format")
    path: str = Field(min_length=1, description="a .csv log or a folder of them, relative to "
                      "the recordings dir (or absolute)")
    lines: str = Field("", description="a CSV of lines drawn under the agents, relative to the "
                       "recordings dir; '' = none")
    held_out_fraction: float = Field(0.25, gt=0, lt=1, description="share (0-1) of the "
                                     "recordings held out for the trials, evenly spaced by "
                                     "name (one recording: its last part in time)")


class AgentLook(StrictModel):
    """How the robot and the human are drawn (both alike)."""

    kind: Literal["car", "disc"] = Field("car", description="the agents' drawn shape: a "
                                         "rectangle along the heading, or a disc")
    length_m: float = Field(4.6, gt=0, description="drawn length (m, > 0), and the size of an "
                            "agent whose recording gives none")
    width_m: float = Field(1.9, gt=0, description="drawn width (m, > 0), likewise")


class RecordedConfig(StrictModel):
    """How recordings become a world's trajectories, trials and start states."""

    kind: Literal["recorded"] = Field(description="`recorded`: this world is read from "
                                      "recordings, not simulated")
    source: Annotated[InteractionSource | CsvSource, Field(
        discriminator="format", description="where the recordings are and what is held out, "
        "by `format`")]
    dt_s: float = Field(0.4, gt=0, description="one step of the clips and the predictions; a "
                        "whole number of the recordings' time steps")
    window_s: float = Field(4.0, gt=0, description="one interaction: a robot/human pair over "
                            "window_s / frame step samples (a v1.2 case: 40 at 10 Hz), "
                            "every dt_s of them kept")
    window_stride_s: float = Field(4.0, gt=0, description="continuous recordings: a window "
                                   "every this many seconds")
    pair_max_distance_m: float = Field(30.0, gt=0, description="robot and human come this "
                                       "close at some step of the window")
    max_pairs: int = Field(0, ge=0, description="0 = every pair; else an even subsample of "
                           "the training and of the held-out pairs")
    turn_threshold_deg: float = Field(30.0, gt=0, description="a heading change over the "
                                      "window larger than this labels it a turn")
    min_moving_speed_mps: float = Field(1.0, ge=0, description="a segment ends only where the "
                                        "robot moves at least this fast (a person cannot "
                                        "click a car standing still)")
    start_heading_tolerance_deg: float = Field(30.0, gt=0, le=180, description="a start state "
                                               "is drawn only where recorded robots drove "
                                               "within this of the robot's heading")
    policy_radius_m: float = Field(4.0, gt=0, description="the recorded future from a start: "
                                   "the nearest recorded robot state within this, heading "
                                   "within the tolerance")
    agent: AgentLook = Field(AgentLook(), description="how the robot and the human are drawn")
    view_span_m: float = Field(60.0, gt=0, description="the clip view: a square this wide "
                               "that follows the robot")
    driven_cell_m: float = Field(2.0, gt=0, description="cell size of the driven area drawn "
                                 "under the clips")
    scene_margin_m: float = Field(5.0, ge=0, description="space (m, >= 0) the scene's bounds "
                                  "leave around every pair's positions")

    @model_validator(mode="after")
    def _windows_hold_a_trial(self) -> "RecordedConfig":
        if self.window_s < MIN_WINDOW_STEPS * self.dt_s:
            raise ValueError(f"window_s: {self.window_s:g} s holds {self.window_s / self.dt_s:g} "
                             f"steps of {self.dt_s} s; a trial needs {MIN_WINDOW_STEPS} (the "
                             "shortest segment, 5 steps, 3 steps to predict and a step of slack "
                             "for the window's first and last frames)")
        return self
