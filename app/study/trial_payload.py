"""What a browser, a pilot bot and a simulated participant are shown and told for one trial.

The part that is the same for everyone: the scene, dt, the example clips and the segment,
the start states (without how each was chosen) and the click limits. The server adds the
participant's step fields (a random `trial_id` ref, numbering) and the prediction view; the
simulated study adds the bank's trial id and world.
"""

import numpy as np

from app.study.trials import POS_DECIMALS, TrialBank, TrialRecord, WorldBank


def trial_payload(bank: TrialBank, trial: TrialRecord) -> dict:
    """Scene, clips, start states and click limits of one trial, as the page receives them."""
    return world_trial_payload(bank.world(trial.world), bank.data.steps_to_predict, trial)


def world_trial_payload(world: WorldBank, steps_to_predict: int, trial: TrialRecord) -> dict:
    """`trial_payload` from one world's bank (also one being built)."""
    return {"scene": world.scene, "dt_s": world.dt_s, **trial.browser_payload(),
            "steps_to_predict": steps_to_predict,
            "max_step_m": world.max_step_m, "min_step_m": world.min_step_m}


def predictor_inputs(world: WorldBank, steps_to_predict: int, trial: TrialRecord) -> tuple:
    """What every predictor is asked for one trial (app/predictors/protocol.py's `ask`): the
    history, start states, robot headings, dt, steps and the trial as it is shown."""
    starts = [[s.robot, s.human] for s in trial.start_states]
    headings = [s.robot_heading for s in trial.start_states]
    return (trial.model_input, starts, headings, world.dt_s, steps_to_predict,
            world_trial_payload(world, steps_to_predict, trial))


def practice_feedback(world: WorldBank, trial: TrialRecord) -> dict:
    """Where the robot goes from each start state of a practice trial: the positions [K, n, 2]
    (m) its own policy's moves (the bank's `policy_actions`) reach, shown once the practice is
    answered. Only practice trials have it: a scored trial's answer never leaves the server."""
    if trial.kind != "practice":
        raise ValueError(f"{trial.trial_id}: only a practice trial's robot moves are shown")
    starts = np.array([s.robot for s in trial.start_states])[:, None, :]
    reached = starts + np.cumsum(np.asarray(trial.policy_actions) * world.dt_s, axis=1)
    return {"robot": np.round(reached, POS_DECIMALS).tolist()}
