"""When training stops, and the record of how it stopped.

Training stops on validation convergence: once the validation loss has not improved by more
than MIN_IMPROVEMENT for `patience_epochs` epochs in a row (stopped_by "patience",
converged), or at the cap `max_epochs` (stopped_by "cap", not converged: the loss was still
improving within the last `patience_epochs` epochs). The weights kept are the best epoch's.

Every checkpoint's metrics.json records `epochs_run`, `best_epoch` (0-based, as the history's
`epoch`), `converged` and `stopped_by`. A metrics file written before these keys existed gets
them by replaying its `history` through the same rule (`stopping_of`).
"""

import math
from dataclasses import dataclass

MIN_IMPROVEMENT = 1e-5  # a smaller fall of the validation loss does not count as better
PATIENCE, CAP = "patience", "cap"


@dataclass
class EarlyStopping:
    """The stopping rule, fed one validation loss per epoch."""

    patience: int
    best: float = math.inf
    best_epoch: int = -1
    stale: int = 0

    def improved(self, epoch: int, loss: float) -> bool:
        """Record one epoch's validation loss; True when it is the new best."""
        if loss < self.best - MIN_IMPROVEMENT:
            self.best, self.best_epoch, self.stale = loss, epoch, 0
            return True
        self.stale += 1
        return False

    @property
    def done(self) -> bool:
        """True once `patience` epochs in a row brought no improvement."""
        return self.stale >= self.patience


def stopping_record(history: list[dict], patience: int) -> dict:
    """epochs_run, best_epoch, converged and stopped_by of a training history (rows with
    `epoch` and `val_total`), by the rule `fit` stops on."""
    rule = EarlyStopping(patience)
    for row in history:
        rule.improved(row["epoch"], row["val_total"])
        if rule.done:
            break
    stopped_by = PATIENCE if rule.done else CAP
    return {"epochs_run": len(history), "best_epoch": rule.best_epoch,
            "converged": stopped_by == PATIENCE, "stopped_by": stopped_by}


def stopping_of(metrics: dict) -> dict:
    """How a checkpoint's training stopped, from its metrics.json: its own record, or one
    replayed from its history (older metrics lack the keys); with its max_epochs."""
    keys = ("epochs_run", "best_epoch", "converged", "stopped_by")
    config = metrics["train_config"]
    if all(key in metrics for key in keys):
        record = {key: metrics[key] for key in keys}
    else:
        record = stopping_record(metrics["history"], config["patience_epochs"])
    return record | {"max_epochs": config["max_epochs"]}

