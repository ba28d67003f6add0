"""How two bundles of one study differ: files, checkpoints, trials and the models' answers.

`tomstudy bundle build` compares the bundle it froze with the one that ships, so a rebuild on
another machine says what it changed: which files and checkpoints differ (CPU float
differences make the same seed train other weights), which trials the two banks share (same id
and the same clip shown), and on those the largest angle and distance between the two
bundles' stored answers per model and seed.
"""

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from app.bank.bundle import BANK, MANIFEST, Bundle, shipped_dir
from app.bank.model_answers import largest_angle_deg
from app.bank.served import simulation_inputs
from app.bank.verify import open_bundle
from app.settings import Settings


def compare_with_shipped(settings: Settings, study_id: str, built: Bundle,
                         replications: int) -> Iterator[str]:
    """What `bundle build` says of `built` against the shipped bundle, line by line as each
    is ready: the differences, then the instrument verdict on each bank (nothing without a
    shipped bundle; BundleError if it cannot be opened)."""
    root = shipped_dir(settings.configs_dir, study_id)
    if not (root / MANIFEST).is_file():
        return
    shipped = open_bundle(root)
    yield from diff_lines(compare_bundles(shipped, built), shipped.root)
    yield from instrument_verdicts(settings, study_id, {"shipped": shipped, "built": built},
                                   replications)


def diff_lines(diff: dict, shipped_root: Path) -> list[str]:
    """`compare_bundles`' result as text: files, checkpoints, then kept trials and answer gaps
    per world."""
    files, rows = diff["files"], diff["checkpoints"]
    lines = [f"\nagainst the shipped bundle {shipped_root}:\n"
             f"content {'identical' if diff['content_same'] else 'differs'}; files: "
             f"{len(files['same'])} same, {len(files['changed'])} changed, "
             f"{len(files['only_old'])} only shipped, {len(files['only_new'])} only built"]
    others = sorted({key for row in rows for key in row["other_keys_differ"]})
    lines.append(f"checkpoints: {sum(row['same'] for row in rows)} of {len(rows)} identical; "
                 f"{sum(row['same_weights'] for row in rows)} of {len(rows)} with the same "
                 f"weights" + (f" (other recorded keys that differ: {', '.join(others)})"
                              if others else ""))
    for world, part in diff["worlds"].items():
        lines.append(f"{world}: {part['main_same_clip']} of {part['main_trials'][0]} shipped "
                     f"main trials kept with the same clip; {part['trials_same_clip']} trials "
                     f"compared")
        lines += [f"  {row['model']:<5} seed {row['seed']}: largest angle "
                  f"{row['max_degrees']:.3g} deg, {row['max_metres']:.3g} m per step, "
                  f"{row['codes_differ']} of {row['trials']} codes differ"
                  for row in part["answers"]]
    return lines


def instrument_verdicts(settings: Settings, study_id: str, bundles: dict[str, Bundle],
                        replications: int) -> Iterator[str]:
    """The instrument check's verdict and pass rate per world on each named bundle's bank."""
    from app.observers.instrument_tables import verdict_line
    from app.observers.simulated_study import run_instrument

    out = settings.layout.instrument_report(study_id)
    for name, bundle in bundles.items():
        inputs = simulation_inputs(settings, study_id, bank=bundle.root / BANK)
        summary = run_instrument(inputs.bank, inputs.trials_per_world, out / f"bundle-{name}",
                                 observers=inputs.observers, replications=replications)
        yield verdict_line(name, summary)


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
    (an older checkpoint's content hash also covers the data's simulation wall time)."""
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
