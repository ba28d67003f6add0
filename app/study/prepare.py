"""Run whatever a study still lacks: simulate both worlds, train both models, build the bank.

Each step is skipped when its output exists (and, for the bank, still matches the
checkpoints it was built from), so `make serve` on a fresh clone does everything once
and later starts in seconds. The steps are the ones `tomstudy simulate`, `train` and
`build-trials` run (`simulate`, `train_world`, `build_trials`), so they write the same files.
"""

import json
from collections.abc import Callable
from pathlib import Path

from pydantic import ValidationError

from app.fileio import sha256_file
from app.layout import Layout
from app.settings import Settings
from app.study.config import StudyConfig, load_study_config


def prepare_study(settings: Settings, study_id: str, n_trajectories: int = 2000,
                  seed: int = 0, say: Callable[[str], None] = print) -> Path:
    """Simulate, train and build-trials as needed for `study_id`; returns the bank path."""
    config = load_study_config(settings, study_id)
    layout = settings.layout
    for world in config.worlds:
        ensure_trajectories(layout, world, n_trajectories, seed, say)
        ours = layout.resolve(config.models[world].ours)
        ensure_checkpoint(layout, world, "ours", ours, seed, say)
        ensure_checkpoint(layout, world, "vae", layout.resolve(config.models[world].vae), seed,
                          say, ours_checkpoint=ours)
    bank = layout.bank(study_id)
    if bank_is_current(bank, config):
        say(f"{bank} is up to date; skipping build-trials")
        return bank
    from app.study.trial_builder import build_trials

    say(f"building the trial bank of {study_id}")
    return build_trials(config, study_id, layout.root)


def missing_inputs(settings: Settings, study_id: str) -> list[Path]:
    """The files a server of `study_id` needs that do not exist (config errors raise)."""
    config = load_study_config(settings, study_id)
    layout = settings.layout
    needed = [layout.bank(study_id)]
    needed += [layout.resolve(getattr(config.models[w], model_name))
               for w in config.worlds for model_name in ("ours", "vae")]
    return [path for path in needed if not path.is_file()]


def ensure_trajectories(layout: Layout, world: str, n: int, seed: int, say) -> None:
    """Simulate a world unless its trajectory file exists."""
    npz_path = layout.trajectories(world)
    if npz_path.is_file() and layout.trajectories_meta(world).is_file():
        say(f"{npz_path} exists; skipping simulate")
        return
    from app.worlds.simulate import simulate

    say(f"simulating {n} {world} trajectories")
    simulate(world, n, seed, layout.root)


def ensure_checkpoint(layout: Layout, world: str, model_name: str, checkpoint: Path, seed: int,
                      say, ours_checkpoint: Path | None = None) -> None:
    """Train one model unless its checkpoint exists (written to checkpoint.parent; the VAE's
    k-means k comes from `ours_checkpoint`)."""
    if checkpoint.is_file():
        say(f"{checkpoint} exists; skipping train")
        return
    from app.learning.config import load_train_config
    from app.learning.train import train_world

    say(f"training {model_name} on {world}")
    written = train_world(layout, world, model_name, seed, load_train_config(), checkpoint.parent,
                          ours_checkpoint)
    if written != checkpoint:
        raise RuntimeError(f"training wrote {written}, the study config expects {checkpoint}")


# the study config's keys that shape the trial bank: a change to any of them rebuilds it
BANK_DESIGN_KEYS = ("worlds", "examples_per_trial", "segment_steps", "start_states",
                    "steps_to_predict", "practice_trials", "bank_trials_per_world", "bank_seed",
                    "main_trial_selection", "prediction_input", "models")
BANK_ATTENTION_KEYS = ("per_world", "candidate_max_angle_deg")  # the rest only score answers


def bank_design(config: dict) -> dict | None:
    """The bank-shaping part of a study config (validated, so defaults count), or None if the
    config no longer validates."""
    try:
        valid = StudyConfig.model_validate(config).model_dump(mode="json")
    except ValidationError:
        return None
    design = {key: valid[key] for key in BANK_DESIGN_KEYS}
    return design | {"attention_checks": {k: valid["attention_checks"][k]
                                          for k in BANK_ATTENTION_KEYS}}


def bank_is_current(bank: Path, config: StudyConfig) -> bool:
    """True if the bank exists, was built with this config's bank design, and its checkpoints
    and trajectories are unchanged."""
    meta_path = bank.with_name("meta.json")
    if not bank.is_file() or not meta_path.is_file():
        return False
    meta = json.loads(meta_path.read_text())
    stored = bank_design(meta.get("config", {}))
    if stored is None or stored != bank_design(config.model_dump(mode="json")):
        return False
    for world in meta.get("worlds", {}).values():
        inputs = [(world["trajectories"], world["trajectories_sha256"])]
        inputs += [(c["path"], c["file_sha256"]) for c in world["checkpoints"].values()]
        for path, digest in inputs:
            if not Path(path).is_file() or sha256_file(Path(path)) != digest:
                return False
    return sha256_file(bank) == meta.get("bank_sha256")
