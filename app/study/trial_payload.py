"""What a browser, a pilot bot and a simulated participant are shown and told for one trial.

The part that is the same for everyone: the scene, dt, the example clips and the segment,
the start states (without how each was chosen) and the click limits. The server adds the
participant's step fields (a random `trial_id` ref, numbering) and the prediction view; the
simulated study adds the bank's trial id and world.
"""

from app.study.trials import TrialBank, TrialRecord, WorldBank


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
