"""Ours' codes against the generator's manoeuvres: levels chosen first, then purity vs a ceiling.

The order keeps any purity score from steering the codebook:
1. `choose_levels`: every cell of `code_levels.levels` (study_configs/interaction.yaml) trains
   Ours once (seed `code_levels.seed`) on the train pairs and is scored by validation task
   loss on the trainer's validation split of those pairs; the rule of `tomstudy select`
   (app/learning/select.py, `choose_ours`) picks the levels every seed then trains with.
   No label and no val pair is read.
2. `ceiling_scores`: a supervised classifier (CEILING) per label, fitted on the same train
   windows Ours fits on (its encoder inputs, standardised) and scored on the val windows
   Ours' purity is computed on: what the observed 1 s can tell about the label.
3. `code_purity`: per label, Ours' purity and NMI (mean over seeds), the VAE's, the ceiling,
   chance (the majority label's share) and Ours as a share of the ceiling.

Purity is in-sample (each code's majority label is taken on the val windows it is scored
on), so it never falls below chance; the ceiling is out-of-sample and can. `held_out` is
Ours' codes used the same way as the ceiling: each code's majority label on the train
windows, scored on the val windows.
"""

import numpy as np

from app.data.windows import Windows, segment_features
from app.interaction.config import CodeLevelsConfig
from app.learning.config import TrainConfig
from app.learning.jobs import JobPool

CEILING = ("classifier on the standardised encoder inputs of the 1 s observed: logistic "
           "regression or an MLP (scikit-learn, 2 x 64 ReLU units, L2 1e-3, 100 epochs, "
           "random_state 0), whichever is more accurate on the trainer's validation windows "
           "(held-out train pairs)")


def choose_levels(trajs, train_cfg: TrainConfig, grid: CodeLevelsConfig,
                  pool: JobPool | None = None) -> dict:
    """Train and score every levels cell on validation loss (the cells on `pool`'s workers);
    the chosen levels and all rows."""
    from app.learning.select import OursGrid, choose_ours, ours_rule

    rule = OursGrid(levels=grid.levels, min_used_fraction=grid.min_used_fraction,
                    loss_tolerance=grid.loss_tolerance)
    cells = [(trajs, train_cfg, levels, grid.seed) for levels in grid.levels]
    rows = (pool or JobPool(1)).run(levels_cell, cells, "interaction: FSQ levels", "cell")
    chosen, any_eligible = choose_ours(rows, rule)
    for k, row in enumerate(rows):
        row["chosen"] = k == chosen
    return {"levels": rows[chosen]["settings"]["levels"], "rule": ours_rule(rule),
            "any_eligible": any_eligible, "seed": grid.seed, "rows": rows}


def levels_cell(trajs, train_cfg: TrainConfig, levels: list[int], seed: int) -> dict:
    """One cell of the levels grid: Ours trained with `levels`, its validation row."""
    from app.learning.select import score_cell
    from app.learning.train import prepare

    # each cell cuts the same windows again (the split is seeded): a job then sends a worker
    # trajectories, not torch tensors
    return score_cell("ours", {"levels": levels}, train_cfg, prepare(trajs, train_cfg), seed)[0]


def encoder_inputs(windows: Windows) -> np.ndarray:
    """The encoder's features of each window's observed segment, flattened [W, T * 8]."""
    features = segment_features(windows.segment_positions, windows.dt_s)
    return features.reshape(len(windows), -1)


def _candidates() -> list:
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.linear_model import LogisticRegression
    from sklearn.neural_network import MLPClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    warnings.filterwarnings("ignore", category=ConvergenceWarning)  # 100 epochs is the budget
    return [make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000)),
            make_pipeline(StandardScaler(), MLPClassifier((64, 64), alpha=1e-3, max_iter=100,
                                                          random_state=0))]


def _accuracy(model, x: np.ndarray, y: np.ndarray) -> float:
    known = y >= 0
    return float((model.predict(x[known]) == y[known]).mean()) if known.any() else 0.0


def _fit_ceiling(fit: tuple[np.ndarray, np.ndarray], check: tuple[np.ndarray, np.ndarray]):
    """CEILING's candidates fitted on `fit`; the one more accurate on `check`."""
    known = fit[1] >= 0
    models = [model.fit(fit[0][known], fit[1][known]) for model in _candidates()]
    return max(models, key=lambda model: _accuracy(model, *check))


def ceiling_scores(trainer: dict[str, Windows], trainer_labels: dict[str, dict],
                   val: Windows, val_labels: dict[str, np.ndarray],
                   scored: np.ndarray, pool: JobPool | None = None) -> dict[str, float]:
    """Accuracy per label of CEILING on the scored val windows whose label is known;
    `trainer` holds the trainer's 'train' and 'val' windows of the train pairs. The labels'
    fits run on `pool`'s workers (each on one thread, like every job: the same numbers
    on any number of workers)."""
    x = {split: encoder_inputs(trainer[split]) for split in ("train", "val")}
    x_val = encoder_inputs(val)
    names, jobs = [], []
    for name, y_val in val_labels.items():
        y = {split: trainer_labels[split][name] for split in ("train", "val")}
        if not (scored & (y_val >= 0)).any() or len(np.unique(y["train"][y["train"] >= 0])) < 2:
            continue
        names.append(name)
        jobs.append(((x["train"], y["train"]), (x["val"], y["val"]), x_val[scored], y_val[scored]))
    scores = (pool or JobPool(1)).run(ceiling_accuracy, jobs, "interaction: ceilings", "label")
    return dict(zip(names, scores, strict=True))


def ceiling_accuracy(fit: tuple[np.ndarray, np.ndarray], check: tuple[np.ndarray, np.ndarray],
                     x: np.ndarray, y: np.ndarray) -> float:
    """One label's ceiling (fitted on `fit`, chosen on `check`) scored on (x, y)."""
    return _accuracy(_fit_ceiling(fit, check), x, y)


def held_out_purity(train_codes: np.ndarray, train_labels: np.ndarray, val_codes: np.ndarray,
                    val_labels: np.ndarray) -> float:
    """Accuracy on val of each code's majority label on the train windows (a code unseen in
    train gets the train majority label); windows with unknown labels are left out."""
    known = train_labels >= 0
    fallback = int(np.bincount(train_labels[known]).argmax())
    guess = {int(c): int(np.bincount(train_labels[known & (train_codes == c)]).argmax())
             for c in np.unique(train_codes[known])}
    scored = val_labels >= 0
    predicted = np.array([guess.get(int(c), fallback) for c in val_codes[scored]])
    return float((predicted == val_labels[scored]).mean())


def code_purity(per_seed: list[dict], ceiling: dict[str, float]) -> dict:
    """label -> Ours' and the VAE's purity and NMI (mean over seeds), ceiling, chance, and
    Ours' purity as a share of the ceiling (and of the ceiling's gain over chance)."""
    out = {}
    for name, ceil in ceiling.items():
        ours = [r["ours"]["agreement"][name] for r in per_seed]
        vae = [r["vae"]["agreement"][name] for r in per_seed]
        purity = float(np.mean([a["purity"] for a in ours]))
        chance = ours[0]["majority"]
        out[name] = {
            "ours": purity, "ours_sd": _sd([a["purity"] for a in ours]),
            "held_out": float(np.mean([r["ours"]["held_out"][name] for r in per_seed])),
            "nmi": float(np.mean([a["nmi"] for a in ours])),
            "vae": float(np.mean([a["purity"] for a in vae])),
            "vae_nmi": float(np.mean([a["nmi"] for a in vae])),
            "ceiling": ceil, "chance": chance,
            "share_of_ceiling": purity / ceil if ceil > 0 else None,
            "share_of_gain": (purity - chance) / (ceil - chance) if ceil > chance else None,
            "n_windows": ours[0]["n_windows"],
        }
    return out


def _sd(values: list[float]) -> float:
    return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
