"""The prediction screen's scale: how many CSS pixels one scene metre spans, per world.

One rule, applied where a trial is served (app/server/state.py hands `view` to the page,
which draws with it) and where clicks are simulated (the instrument reads the same
resolution). The scale makes the world policy's median true step, from the main trials'
start states, span TARGET_STEP_PX: a click one pixel off then turns the move by
`click_resolution_deg` degrees. It is the same on every screen the study accepts (at least
900 x 600), so every participant's clicks carry the same angular resolution; a larger window
shows more of the scene around the robot, not a larger one.

Input is a world of the trial bank as stored in bank.json (`dt_s` and each trial's `kind`
and `policy_actions` [K, n, 2] in m/s), so the observers, which never import the web
server, read it from the file as the server does.
"""

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

TARGET_STEP_PX = 60.0  # a typical robot step spans this many CSS pixels
MIN_WINDOW_PX = {"width": 900, "height": 600}  # the smallest window the study runs in
SCORED_KIND = "main"  # the trials whose answers are analysed
# what of a world's bank (a WorldBank's model_dump(include=...)) the view's scale reads
VIEW_FIELDS = {"dt_s": True, "trials": {"__all__": {"kind": True, "policy_actions": True}}}


@dataclass(frozen=True)
class PredictionView:
    """The prediction screen of one world: its pixel scale and the step it is built on."""

    px_per_m: float  # CSS pixels per scene metre
    median_step_m: float  # the policy's median true step (m)

    @property
    def median_step_px(self) -> float:
        """The median true step on screen (CSS px)."""
        return self.median_step_m * self.px_per_m

    @property
    def resolution_deg(self) -> float:
        """Degrees a move at the median true step turns per pixel of click error."""
        return math.degrees(math.atan2(1.0, self.median_step_px))

    def payload(self) -> dict:
        """What the page draws with (the trial payload's `view`)."""
        return {"px_per_m": self.px_per_m, "median_step_m": self.median_step_m,
                "target_step_px": TARGET_STEP_PX}


def true_step_lengths_m(world_bank: Mapping) -> np.ndarray:
    """Lengths (m) of the world policy's moves from every main trial's start states."""
    actions = [np.asarray(t["policy_actions"], dtype=np.float64)
               for t in world_bank["trials"] if t["kind"] == SCORED_KIND]
    if not actions:
        raise ValueError("trials: the world has no main trial to size the prediction view on")
    return np.linalg.norm(np.concatenate([a.reshape(-1, 2) for a in actions]), axis=1) \
        * float(world_bank["dt_s"])


def prediction_view(world_bank: Mapping) -> PredictionView:
    """The scale that makes the median true step span TARGET_STEP_PX."""
    median = float(np.median(true_step_lengths_m(world_bank)))
    if not median > 0:
        raise ValueError("trials.policy_actions: the robot's median true step is 0 m; "
                         "no scale can show its direction")
    return PredictionView(px_per_m=round(TARGET_STEP_PX / median, 3),
                          median_step_m=round(median, 4))


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
