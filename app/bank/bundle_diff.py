"""How two bundles of one study differ: files, checkpoints, trials and the models' answers.

`tomstudy bundle build` compares the bundle it froze with the one that ships, so a rebuild on
another machine says what it changed: which files and checkpoints differ (CPU float
differences make the same seed train other weights), which trials the two banks share (same id
and the same clip shown), and on those the largest angle and distance between the two
bundles' stored answers per model and seed.
"""

import numpy as np

from app.bank.bundle import Bundle
from app.bank.model_answers import largest_angle_deg


def compare_bundles(old: Bundle, new: Bundle) -> dict:
    """Files, checkpoints, trials and answers of `new` against `old` (JSON-able)."""
    return {"old": str(old.root), "new": str(new.root),
            "content_same": old.manifest["content_sha256"] == new.manifest["content_sha256"],
            "bank_same": old.bank.sha256 == new.bank.sha256,
            "files": compare_files(old.manifest["files"], new.manifest["files"]),
            "checkpoints": [row | same_weights(old, new, row) for row in
                            compare_checkpoints(old.manifest["models"], new.manifest["models"])],
            "worlds": {world: compare_world(old, new, world)
                       for world in sorted(set(old.bank.data.worlds) & set(new.bank.data.worlds))}}


def compare_files(old: dict, new: dict) -> dict:
    """Names of files that are the same, changed, or in one bundle only."""
    common = set(old) & set(new)
    return {"same": sorted(n for n in common if old[n]["sha256"] == new[n]["sha256"]),
            "changed": sorted(n for n in common if old[n]["sha256"] != new[n]["sha256"]),
            "only_old": sorted(set(old) - common), "only_new": sorted(set(new) - common)}


def compare_checkpoints(old: dict, new: dict) -> list[dict]:
    """Per world, model and seed: whether the two bundles hold the same checkpoint."""
    rows = []
    for world in sorted(set(old) | set(new)):
        for model in sorted(set(old.get(world, {})) | set(new.get(world, {}))):
            a, b = old.get(world, {}).get(model, {}), new.get(world, {}).get(model, {})
            for seed in sorted(set(a) | set(b), key=int):
                rows.append({"world": world, "model": model, "seed": int(seed),
                             "old": a.get(seed, ""), "new": b.get(seed, ""),
                             "same": a.get(seed) == b.get(seed)})
    return rows


def same_weights(old: Bundle, new: Bundle, row: dict) -> dict:
    """Whether a checkpoint pair holds the same weights, and which other recorded keys differ
    (a content hash also covers what the data's simulation recorded, its wall time say)."""
    if row["same"] or not (row["old"] and row["new"]):  # a content hash covers the weights
        return {"same_weights": row["same"], "other_keys_differ": []}
    a, b = (bundle.model(row["world"], row["model"], row["seed"]) for bundle in (old, new))
    keys = ("data_meta", "data_hash", "train_config", "codes", "model_args")
    return {"same_weights": a.same_weights(b),
            "other_keys_differ": [k for k in keys if getattr(a, k) != getattr(b, k)]}


def compare_world(old: Bundle, new: Bundle, world: str) -> dict:
    """One world's trials in both banks, and the largest gaps between their stored answers."""
    a = {t.trial_id: t for t in old.bank.world(world).trials}
    b = {t.trial_id: t for t in new.bank.world(world).trials}
    shared = sorted(tid for tid in set(a) & set(b) if a[tid].clip_sha256 == b[tid].clip_sha256)
    main_a = {tid for tid, t in a.items() if t.kind == "main"}
    main_b = {tid for tid, t in b.items() if t.kind == "main"}
    return {"trials_same_clip": len(shared),
            "trials_other_clip": len(set(a) & set(b)) - len(shared),
            "only_old": len(set(a) - set(b)), "only_new": len(set(b) - set(a)),
            "main_same_clip": len(main_a & main_b & set(shared)),
            "main_trials": [len(main_a), len(main_b)],
            "answers": answer_gaps([a[tid] for tid in shared], [b[tid] for tid in shared],
                                   old.bank.world(world).dt_s)}


def answer_gaps(old_trials: list, new_trials: list, dt_s: float) -> list[dict]:
    """Per model and seed, over trials that show the same clip: the largest angle [deg] and
    one-step distance [m] between the two bundles' stored answers, and codes that differ."""
    gaps: dict[tuple, dict] = {}
    for old, new in zip(old_trials, new_trials, strict=True):
        for model, family in old.predictions.items():
            others = {answer.seed: answer for answer in new.predictions.get(model, [])}
            for answer in family:
                if answer.seed not in others:
                    continue
                a = np.asarray(answer.actions, dtype=np.float64)
                b = np.asarray(others[answer.seed].actions, dtype=np.float64)
                row = gaps.setdefault((model, answer.seed), {
                    "model": model, "seed": answer.seed, "trials": 0, "max_degrees": 0.0,
                    "max_metres": 0.0, "codes_differ": 0})
                row["trials"] += 1
                row["max_degrees"] = max(row["max_degrees"], largest_angle_deg(a, b))
                row["max_metres"] = max(row["max_metres"],
                                        float(np.linalg.norm(a - b, axis=-1).max()) * dt_s)
                row["codes_differ"] += int(answer.code != others[answer.seed].code)
    return [gaps[key] for key in sorted(gaps)]
