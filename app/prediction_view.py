"""The prediction screen's scale: how many CSS pixels one scene metre spans, per world.

One rule, applied where a trial is served (app/server/flow/state.py hands `view` to the page,
which draws with it) and where clicks are simulated (the instrument reads the same
resolution). The scale makes the world policy's median true step, from the main trials'
start states, span TARGET_STEP_PX: a click one pixel off then turns the move by
`click_resolution_deg` degrees. It is the same on every screen the study accepts (at least
900 x 600), so every participant's clicks carry the same angular resolution; a larger window
shows more of the scene around the robot, not a larger one.

The robot's outline at its start (the rule `tomstudy check-display` measures per world,
app/bank/display_check.py): a move is measured from the robot's centre, and a recorded car
moves far less than its length in one step (at the intersection, 1.3 m in 0.4 s against a
4.6 m car), so the first click would land inside the car as drawn; no pixel scale changes
that, since both are metres. So a recorded world's prediction view draws its agents at
`outline_scale` of their size: the robot's half-length (its median over the main trials,
each at its recorded size) spans at most OUTLINE_STEP_SHARE of the median true step, so a
click at the median step lands clear of the drawn nose by a quarter of a step (15 px), more
than a click ring's radius, and the outline stays well inside the reach circle. The robot
is drawn see-through (a tint inside its outline: clicks, the path and the reach disc stay
visible through it); the clip player draws every agent at its own size. A simulated world
(Highway, Obstacle) keeps its agents at their size: its screens are frozen with the paper
study, and check-display reports its figures against the same rule all the same.

Input is a world of the trial bank as stored in bank.json (`dt_s` and each trial's `kind`
and `policy_actions` [K, n, 2] in m/s; for the outline, the scene's `agents` and `recorded`
and each trial's `segment.sizes`), so the observers, which never import the web server, read
it from the file as the server does.
"""

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

TARGET_STEP_PX = 60.0  # a typical robot step spans this many CSS pixels
MIN_WINDOW_PX = {"width": 900, "height": 600}  # the smallest window the study runs in
SCORED_KIND = "main"  # the trials whose answers are analysed
OUTLINE_STEP_SHARE = 0.75  # a recorded robot's drawn half-length, in median true steps, at most
OUTLINE_REACH_SHARE = 0.5  # and the drawn half-length, in reach radii, at most (checked only)
# what of a world's bank (a WorldBank's model_dump(include=...)) the view's scale reads
VIEW_FIELDS = {"dt_s": True, "scene": {"agents": True, "recorded": {"source": True}},
               "trials": {"__all__": {"kind": True, "policy_actions": True,
                                      "segment": {"sizes": True}}}}


@dataclass(frozen=True)
class PredictionView:
    """The prediction screen of one world: its pixel scale and the step it is built on."""

    px_per_m: float  # CSS pixels per scene metre
    median_step_m: float  # the policy's median true step (m)
    outline_scale: float = 1.0  # agents are drawn at this share of their size

    @property
    def median_step_px(self) -> float:
        """The median true step on screen (CSS px)."""
        return self.median_step_m * self.px_per_m

    @property
    def resolution_deg(self) -> float:
        """Degrees a move at the median true step turns per pixel of click error."""
        return math.degrees(math.atan2(1.0, self.median_step_px))

    def payload(self) -> dict:
        """What the page draws with (the trial payload's `view`; `outline_scale` only where
        it is below 1, so a simulated world's payload is as before)."""
        shown = {"px_per_m": self.px_per_m, "median_step_m": self.median_step_m,
                 "target_step_px": TARGET_STEP_PX}
        return shown | ({"outline_scale": self.outline_scale} if self.outline_scale < 1 else {})


def true_step_lengths_m(world_bank: Mapping) -> np.ndarray:
    """Lengths (m) of the world policy's moves from every main trial's start states."""
    actions = [np.asarray(t["policy_actions"], dtype=np.float64)
               for t in world_bank["trials"] if t["kind"] == SCORED_KIND]
    if not actions:
        raise ValueError("trials: the world has no main trial to size the prediction view on")
    return np.linalg.norm(np.concatenate([a.reshape(-1, 2) for a in actions]), axis=1) \
        * float(world_bank["dt_s"])


def main_robot_sizes_m(world_bank: Mapping) -> np.ndarray:
    """The robot's (length, width) [M, 2] m in every main trial: its recorded size where the
    segment carries one, else the scene's robot shape."""
    shape = world_bank["scene"]["agents"][0]
    fallback = [shape["length_m"], shape["width_m"]]
    return np.array([(t["segment"].get("sizes") or [fallback])[0]
                     for t in world_bank["trials"] if t["kind"] == SCORED_KIND],
                    dtype=np.float64).reshape(-1, 2)


def outline_scale(world_bank: Mapping, median_step_m: float) -> float:
    """The share of their size a recorded world's agents are drawn at (module docstring):
    the robot's median half-length spans at most OUTLINE_STEP_SHARE median true steps."""
    if not (world_bank.get("scene") or {}).get("recorded"):
        return 1.0
    half_length = float(np.median(main_robot_sizes_m(world_bank)[:, 0])) / 2
    # rounded down, so the drawn outline never exceeds the rule's share
    return math.floor(min(1.0, OUTLINE_STEP_SHARE * median_step_m / half_length) * 1000) / 1000


def prediction_view(world_bank: Mapping) -> PredictionView:
    """The scale that makes the median true step span TARGET_STEP_PX, and the share of their
    size the agents are drawn at."""
    median = float(np.median(true_step_lengths_m(world_bank)))
    if not median > 0:
        raise ValueError("trials.policy_actions: the robot's median true step is 0 m; "
                         "no scale can show its direction")
    return PredictionView(px_per_m=round(TARGET_STEP_PX / median, 3),
                          median_step_m=round(median, 4),
                          outline_scale=outline_scale(world_bank, round(median, 4)))


def click_resolution_deg(world_bank: Mapping) -> float:
    """Angular resolution of one click at the median true step (degrees per pixel of error)."""
    return prediction_view(world_bank).resolution_deg


def view_click_sd_deg(world_bank, click_sd_px: float) -> float:
    """`click_direction_sd_deg` of a world's bank model (a WorldBank, loaded or being built)."""
    return click_direction_sd_deg(world_bank.model_dump(include=VIEW_FIELDS), click_sd_px)


def click_direction_sd_deg(world_bank: Mapping, click_sd_px: float) -> float:
    """Direction SD (deg) of a move at the median true step clicked with `click_sd_px` of
    spread on screen."""
    return math.degrees(math.atan2(click_sd_px, prediction_view(world_bank).median_step_px))
