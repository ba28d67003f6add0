"""The server and the simulated study share one definition of a trial's payload, of what a
click means and of an answered trial's rows: a simulated answer posted to the server is
stored exactly as the simulated study scores it."""

import numpy as np
import pytest
from sqlalchemy import select

from app.bank.model_answers import ACTION_TOLERANCE_MPS
from app.core.contracts import COARSE_OBSERVERS
from app.layout import Layout
from app.observers import inverse_planning
from app.observers.simulated_study import answer_columns, check_answer, simulated_payload
from app.server.storage.tables import PredictionRow
from app.study.errors import Refused
from app.study.trials import TrialBank
from tests.server.flow import Participant, prediction_body, segment_key

# the server stores its own recomputed answers of these (the bank's are rounded to 1e-5 m/s)
MODEL_COLUMNS = {f"{m}_{axis}" for m in ("ours", "vae", *COARSE_OBSERVERS) for axis in ("vx", "vy")}


@pytest.fixture(scope="module")
def trial_bank(small_study) -> TrialBank:
    """The small study's bank, read as the simulated study reads a bank."""
    return TrialBank.read(Layout(small_study.data_dir).bank(small_study.study_id))


def bank_record(bank: TrialBank, payload: dict):
    """The bank trial a served payload shows (the payload's id is an opaque ref)."""
    by_segment = {segment_key(t.segment.positions): t for t in bank.by_id.values()}
    return by_segment[segment_key(payload["segment"]["positions"])]


def stored_rows(client, submission_id: str) -> list[dict]:
    """The PredictionRow rows of one submission, start state major."""
    query = (select(PredictionRow).where(PredictionRow.submission_id == submission_id)
             .order_by(PredictionRow.start_index, PredictionRow.step))
    with client.app.state.engine.connect() as conn:
        return [dict(row._mapping) for row in conn.execute(query)]


def stored(row: dict, column: str):
    """A row's value of an answer column: its own, or a code predictor's from `plugins`."""
    if column in row:
        return row[column]
    name, field = column.rsplit("_", 1)
    return row["plugins"][name][field]


def test_a_simulated_answer_is_stored_as_the_simulated_study_scores_it(client, small_study,
                                                                       trial_bank):
    p = Participant(client, small_study.study_id)
    p.start()
    served = p.pass_intro()["step"]
    trial = bank_record(trial_bank, served)
    simulated = simulated_payload(trial_bank, trial)
    shared = set(simulated) - {"trial_id"}
    assert len(shared) >= 9 and {k: served[k] for k in shared} == {k: simulated[k]
                                                                     for k in shared}
    rng = np.random.default_rng(4)
    clicks = inverse_planning.predict("precise", simulated, rng, trial.policy_actions)
    body = prediction_body(served, clicks.tolist())
    assert p.post("predictions", body).status_code == 201

    rows = stored_rows(client, body["submission_id"])
    expected = answer_columns(trial_bank, trial, clicks)
    assert len(rows) == len(trial.start_states) * served["steps_to_predict"] > 0
    for name, values in expected.items():
        got = [stored(row, name) for row in rows]
        if name in MODEL_COLUMNS:
            np.testing.assert_allclose(got, values, atol=ACTION_TOLERANCE_MPS)
        else:
            assert got == values.tolist(), name


def test_the_simulated_study_refuses_a_click_the_server_refuses(trial_bank):
    trial = next(t for t in trial_bank.by_id.values() if t.kind == "main")
    world = trial_bank.world(trial.world)
    starts = np.asarray([s.robot for s in trial.start_states])
    too_far = starts[:, None, :] + np.arange(1, 4)[None, :, None] * [world.max_step_m * 1.5, 0]
    with pytest.raises(Refused, match=r"points\.0\.0: move of .* longer than the reachable"):
        check_answer(trial_bank, trial, too_far)
