"""Training stops on validation convergence under a cap, and each checkpoint's metrics say
which of the two stopped it."""

import json

import pytest

from app.learning.config import TrainConfig
from app.learning.convergence import stopping_of, stopping_record
from app.learning.train import train_and_save
from tests.learning.synthetic import make_lane_trajs

TINY = {"windows_per_trajectory": 4, "encoder_hidden": [16], "decoder_hidden": [16]}
RECORD_KEYS = ("epochs_run", "best_epoch", "converged", "stopped_by")


@pytest.fixture(scope="module")
def tiny_trajs():
    """60 analytic lane trajectories."""
    return make_lane_trajs(60, seed=1)


def trained_metrics(trajs, tmp_path, **config) -> dict:
    """metrics.json of an Ours trained on `trajs` with the tiny config and `config`."""
    path = train_and_save(trajs, "ours", 0, TrainConfig(**TINY, **config), tmp_path,
                          progress=False)
    return json.loads((path.parent / "metrics.json").read_text())


def history_of(losses: list[float]) -> list[dict]:
    """A training history with these validation losses."""
    return [{"epoch": epoch, "val_total": loss} for epoch, loss in enumerate(losses)]


def test_a_run_that_hits_its_cap_is_recorded_as_not_converged(tiny_trajs, tmp_path):
    metrics = trained_metrics(tiny_trajs, tmp_path, max_epochs=3, patience_epochs=50)
    assert {key: metrics[key] for key in ("epochs_run", "converged", "stopped_by")} == \
        {"epochs_run": 3, "converged": False, "stopped_by": "cap"}
    losses = [row["val_total"] for row in metrics["history"]]
    assert metrics["best_epoch"] == losses.index(min(losses))


def test_a_run_stopped_by_patience_is_recorded_as_converged(tiny_trajs, tmp_path):
    metrics = trained_metrics(tiny_trajs, tmp_path, max_epochs=400, patience_epochs=2)
    assert metrics["converged"] is True and metrics["stopped_by"] == "patience"
    assert metrics["epochs_run"] < 400 and len(metrics["history"]) == metrics["epochs_run"]
    assert metrics["best_epoch"] == metrics["epochs_run"] - 1 - 2  # two epochs without a gain
    # an older metrics file without the keys replays its history to the same record
    older = {key: value for key, value in metrics.items() if key not in RECORD_KEYS}
    assert stopping_of(older) == stopping_of(metrics) == \
        {key: metrics[key] for key in RECORD_KEYS} | {"max_epochs": 400}


def test_the_rule_counts_only_gains_above_the_threshold():
    assert stopping_record(history_of([1.0, 0.5, 0.5, 0.499999]), 2) == {
        "epochs_run": 4, "best_epoch": 1, "converged": True, "stopped_by": "patience"}
    assert stopping_record(history_of([1.0, 0.5, 0.5, 0.4]), 2) == {
        "epochs_run": 4, "best_epoch": 3, "converged": False, "stopped_by": "cap"}
    # stopped by patience on the cap's very epoch: converged, though it ran max_epochs
    assert stopping_record(history_of([1.0, 0.5, 0.6, 0.7]), 2)["stopped_by"] == "patience"
