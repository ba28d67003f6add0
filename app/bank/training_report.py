"""How each checkpoint of a bundle stopped training, read from its metrics file in the bundle.

`bundle build` warns of every checkpoint that hit its max_epochs cap still improving and lists
them in the manifest (`unconverged`); `bundle verify` prints every checkpoint's epochs and
whether it converged. The rule and the record are app/learning/convergence.py's; a bundle
frozen before checkpoints recorded them gets them replayed from each history.
"""

import json
from pathlib import Path

from app.bank.bundle import metrics_file
from app.core.files import read_bytes
from app.learning.convergence import stopping_of


def checkpoint_stopping(root: Path, models: dict) -> list[dict]:
    """World, model, seed and how its training stopped, for every checkpoint of `models` (a
    manifest's world -> model -> seed -> content hash) in the bundle at `root`."""
    rows = []
    for world, family in sorted(models.items()):
        for model, seeds in sorted(family.items()):
            for seed in sorted(int(s) for s in seeds):
                metrics = json.loads(read_bytes(Path(root) / metrics_file(world, model, seed)))
                rows.append({"world": world, "model": model, "seed": seed,
                             **stopping_of(metrics)})
    return rows


def unconverged(rows: list[dict]) -> list[dict]:
    """The checkpoints that hit their cap (the manifest's `unconverged`)."""
    return [row for row in rows if not row["converged"]]


def cap_warning(row: dict, model_dir: Path) -> str:
    """`bundle build`'s warning of a checkpoint (trained into `model_dir`) that hit its cap
    still improving."""
    return (f"WARNING: {row['world']}/{row['model']} seed {row['seed']} did not converge: it "
            f"ran all {row['epochs_run']} of its max_epochs {row['max_epochs']} with the "
            f"validation loss still improving (best epoch {row['best_epoch']}); to train it "
            f"to convergence, raise max_epochs in training.yaml, delete {model_dir} and build "
            f"again")


def stopping_lines(rows: list[dict]) -> list[str]:
    """What `bundle verify` prints of training: epochs run, best epoch, cap and verdict per
    checkpoint."""
    lines = [f"{'world':<14}{'model':<7}{'seed':>5}{'epochs':>8}{'best':>6}{'cap':>6}  training"]
    lines += [f"{r['world']:<14}{r['model']:<7}{r['seed']:>5}{r['epochs_run']:>8}"
              f"{r['best_epoch']:>6}{r['max_epochs']:>6}  "
              f"{'converged' if r['converged'] else 'NOT CONVERGED (hit the cap)'}"
              for r in rows]
    lines.append("epochs = epochs run; best = the epoch whose weights are kept (0-based); "
                 "converged = stopped after patience_epochs without a better validation loss; "
                 "hit the cap = stopped at max_epochs while still improving")
    return lines
