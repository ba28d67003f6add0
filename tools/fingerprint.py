"""Hashes that a refactor must not change: fixed-seed trajectories, the trial bank, bot clicks.

    python -m tools.fingerprint [--n 16] [--seed 3]

Simulates both worlds with a fixed seed into a scratch data dir, builds the paper study's
bank there from the checkpoints under var/models (and the trajectories under var/data), and
lets every bot kind click every trial of that bank with fixed seeds, and runs the simulated
study (the instrument's path) on the shipped bank. Prints one sha256 per artefact; run it
before and after a change that should not alter behaviour and compare.
"""

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BOT_KINDS = ("coarse", "coarse_relative", "precise", "random")


def array_digest(npz_path: Path) -> str:
    """sha256 over every array of an npz file, by name (zip timestamps do not count)."""
    digest = hashlib.sha256()
    with np.load(npz_path, allow_pickle=False) as data:
        for name in sorted(data.files):
            array = np.ascontiguousarray(data[name])
            digest.update(f"{name}:{array.dtype}:{array.shape}".encode())
            digest.update(array.tobytes())
    return digest.hexdigest()


def tomstudy(data_dir: Path, *args: str) -> None:
    """Run one `tomstudy` subcommand against `data_dir`; stop on failure."""
    env = dict(os.environ, TOMSTUDY_DATA_DIR=str(data_dir))
    command = [sys.executable, "-c", "from app.cli import main; main()", *args]
    subprocess.run(command, env=env, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)


def trajectory_digests(scratch: Path, n: int, seed: int) -> dict[str, str]:
    """Simulate both worlds with a fixed seed; sha256 of each trajectory file's arrays."""
    out = {}
    for world in ("highway", "obstacle"):
        tomstudy(scratch, "simulate", world, "--n", str(n), "--seed", str(seed))
        out[f"trajectories/{world}"] = array_digest(scratch / "data" / world / "trajectories.npz")
    return out


def bank_digest(scratch: Path, source: Path) -> tuple[str, Path]:
    """Build paper_study's bank from `source`'s data and models; sha256 of bank.json."""
    for part in ("data", "models"):
        (scratch / part).symlink_to((source / part).resolve())
    tomstudy(scratch, "build-trials", "--study", "paper_study")
    bank = scratch / "trials" / "paper_study" / "bank.json"
    return hashlib.sha256(bank.read_bytes()).hexdigest(), bank


def click_digests(bank_path: Path, seed: int) -> dict[str, str]:
    """Every bot kind clicks every trial of the bank with a fixed seed; sha256 per kind."""
    from app.pilot.bots import choose_clicks, load_policy_actions
    from app.study.trial_payload import trial_payload
    from app.study.trials import TrialBank

    bank = TrialBank.read(bank_path)
    policy = load_policy_actions(bank_path)
    out = {}
    for kind in BOT_KINDS:
        rng = np.random.default_rng(seed)
        digest = hashlib.sha256()
        for trial in bank.by_id.values():
            payload = {**trial_payload(bank, trial), "trial_id": trial.trial_id}
            clicks = choose_clicks(kind, payload, rng, policy)
            digest.update(np.asarray(clicks, dtype=np.float64).tobytes())
        out[f"clicks/{kind}"] = digest.hexdigest()
    return out


def simulated_digests(seed: int) -> dict[str, str]:
    """The simulated study on the shipped bank (8 participants per population, 10 trials per
    world): sha256 of every export column and of the per-participant err_ours - err_vae."""
    from app.observers.config import default_observers
    from app.observers.simulated_study import load_bank, participant_diffs, population_frames

    bank = load_bank(ROOT / "study_configs" / "bundles" / "paper_study" / "bank.json.gz")
    frames = population_frames(bank, 8, 10, seed, default_observers(), show_progress=False)
    out = {}
    for preset, frame in frames.items():
        rows = frame.sort_index(axis=1).to_csv(index=False).encode()
        diffs = participant_diffs(frame).to_csv(index=False).encode()
        out[f"simulated/{preset}"] = hashlib.sha256(rows).hexdigest()
        out[f"simulated/{preset}/diffs"] = hashlib.sha256(diffs).hexdigest()
    return out


def fingerprint(n: int, seed: int, source: Path) -> dict[str, str]:
    """All the hashes, keyed by artefact."""
    with tempfile.TemporaryDirectory() as tmp:
        sim, built = Path(tmp) / "sim", Path(tmp) / "bank"
        sim.mkdir()
        built.mkdir()
        out = trajectory_digests(sim, n, seed)
        out["bank/paper_study"], bank_path = bank_digest(built, source)
        out.update(click_digests(bank_path, seed))
    out.update(simulated_digests(seed))
    return out


def main() -> None:
    """Print the fingerprint as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=16, help="trajectories per world")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--source", type=Path, default=ROOT / "var",
                        help="data dir holding data/ and models/ for the bank")
    args = parser.parse_args()
    print(json.dumps(fingerprint(args.n, args.seed, args.source), indent=2))


if __name__ == "__main__":
    main()
