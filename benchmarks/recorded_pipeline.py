"""Time `tomstudy interaction` and `tomstudy bundle build --study interaction_study` on
real-size recording files, and how the time grows with the number of files.

Generates (once, or reuses `--recordings`) GENERATED, NOT REAL v1.0 files of both study
scenarios at real size (`tomstudy generate-recordings --files N`: `--minutes` of traffic per
file at `--arrivals-per-arm-min`, about 30 cars in view as on a real INTERACTION file), then
for each file count of `--files` runs, as a user does (`tomstudy`, each in its own data dir):
`interaction --data <the first N roundabout files> --scenario DR_USA_Roundabout_FT` and
`bundle build --study interaction_study` (both worlds, N files each). Each run's phases come
from its artefacts: the interaction report's meta.json (`phase_wall_time_s`) and the
bundle's manifest (`built.phase_wall_time_s`); per recording file (the load / data phase),
per selection cell and per checkpoint; `pairs` is the training pairs the models fit on (the
bundle's: both worlds', after their `max_pairs` cap). `--baseline-code DIR` first runs the
same commands with another checkout (e.g. `git worktree add ../before <commit>`) on the same
files and prints the before/after ratios and whether the results are identical (checkpoint
hashes, bank, per-seed errors, the ceilings). The growth line divides each count's time by
the smallest count's. Training keeps training.yaml's epochs and the study's seeds unless
`--seeds` / `--max-epochs` cut them (quick checks only: the target is for the study's rules).

    .venv/bin/python benchmarks/recorded_pipeline.py [--files 1,2,4,6] [--minutes 15]
        [--recordings DIR] [--baseline-code DIR] [--commands interaction,bundle]
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

STUDY = "interaction_study"
ROUNDABOUT = "DR_USA_Roundabout_FT"
SCENARIOS = (ROUNDABOUT, "DR_USA_Intersection_EP0")
TARGET_S = 300.0
CODE = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-c", "from app.cli import main; main()"]  # any checkout's `tomstudy`


def cpu_s() -> float:
    """CPU seconds of this process's finished child processes (the commands and workers)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def generate(folder: Path, files: int, minutes: float, rate: float | None,
             scenarios: tuple[str, ...]) -> None:
    """Real-size generated files of both scenarios, unless `folder` already holds enough of
    the `scenarios` the commands read."""
    have = [len(list((folder / "recorded_trackfiles" / s).glob("vehicle_tracks_*.csv")))
            for s in scenarios]
    if min(have) >= files:  # an interrupted run leaves one scenario short
        return
    args = ["generate-recordings", "--out", str(folder), "--files", str(files),
            "--seconds", str(minutes * 60)]
    if rate is not None:
        args += ["--arrivals-per-arm-min", str(rate)]
    subprocess.run([*CLI, *args], cwd=CODE, check=True,
                   env={**os.environ, "PYTHONPATH": str(CODE)}, stdout=subprocess.DEVNULL)


def first_files(source: Path, files: int, out: Path, scenarios: tuple[str, ...]) -> Path:
    """A folder whose recorded_trackfiles, labels and maps are links to the first `files`
    recordings of each of `scenarios` (their sidecar labels and the maps)."""
    for scenario in scenarios:
        folder = out / "recorded_trackfiles" / scenario
        folder.mkdir(parents=True)
        for k in range(files):
            for kind in ("vehicle", "pedestrian"):
                name = f"{kind}_tracks_{k:03d}.csv"
                (folder / name).symlink_to(source / "recorded_trackfiles" / scenario / name)
            label = f"{scenario}_vehicle_tracks_{k:03d}.csv"
            (out / "generator_labels").mkdir(exist_ok=True)
            (out / "generator_labels" / label).symlink_to(source / "generator_labels" / label)
    (out / "maps").symlink_to(source / "maps")
    return out


def configs(code: Path, out: Path, seeds: int | None, max_epochs: int | None) -> Path:
    """The checkout's study_configs without shipped bundles, cut where asked."""
    shutil.copytree(code / "study_configs", out, ignore=shutil.ignore_patterns("bundles"))
    if seeds is not None:
        study = yaml.safe_load((out / f"{STUDY}.yaml").read_text())
        study["models"] = {"seeds": list(range(seeds))}
        (out / f"{STUDY}.yaml").write_text(yaml.safe_dump(study))
        interaction = yaml.safe_load((out / "interaction.yaml").read_text())
        interaction["seeds"] = seeds
        interaction["frame_sensitivity"]["seeds"] = min(seeds, 5)
        (out / "interaction.yaml").write_text(yaml.safe_dump(interaction))
    if max_epochs is not None:
        training = yaml.safe_load((out / "training.yaml").read_text())
        training["max_epochs"] = max_epochs
        (out / "training.yaml").write_text(yaml.safe_dump(training))
    return out


def run(code: Path, env: dict, args: list[str]) -> tuple[float, float]:
    """Run `tomstudy ARGS` from the checkout `code`; its wall and CPU seconds."""
    wall, cpu = time.perf_counter(), cpu_s()
    done = subprocess.run([*CLI, *args], cwd=code,
                          env={**os.environ, **env, "PYTHONPATH": str(code)},
                          capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"{' '.join(args)} failed ({code}):\n{done.stderr[-3000:]}")
    return time.perf_counter() - wall, cpu_s() - cpu


def interaction_run(code: Path, data: Path, var: Path, configs_dir: Path, files: int) -> dict:
    """`tomstudy interaction` on the roundabout's files: times, phases and results."""
    env = {"TOMSTUDY_DATA_DIR": str(var), "TOMSTUDY_CONFIGS_DIR": str(configs_dir)}
    wall, cpu = run(code, env, ["interaction", "--data", str(data), "--scenario", ROUNDABOUT,
                                "--config", str(configs_dir / "interaction.yaml")])
    out = var / "reports" / "interaction" / ROUNDABOUT
    meta = json.loads((out / "meta.json").read_text())
    cfg = meta["config"]
    cells = len(cfg["code_levels"]["levels"])
    checkpoints = 2 * (cfg["seeds"] + cfg["frame_sensitivity"]["seeds"])
    phases = meta["phase_wall_time_s"]
    pairs = json.loads((out / "summary.json").read_text())["pairs"]["train"]
    return {"wall": wall, "cpu": cpu, "phases": phases, "pairs": pairs,
            "per_file": phases["load"] / files, "per_cell": phases["levels"] / cells,
            "per_checkpoint": phases["seeds"] / checkpoints,
            "results": {"checkpoints": meta["checkpoints"],
                        "per_seed": (out / "per_seed.csv").read_text().replace(str(var), "VAR"),
                        "code_purity": json.loads((out / "summary.json").read_text())[
                            "code_purity"]}}


def bundle_run(code: Path, data: Path, var: Path, configs_dir: Path, files: int) -> dict:
    """`tomstudy bundle build --study interaction_study`: times, phases and results."""
    env = {"TOMSTUDY_DATA_DIR": str(var), "TOMSTUDY_CONFIGS_DIR": str(configs_dir),
           "TOMSTUDY_RECORDINGS_DIR": str(data.parent)}
    wall, cpu = run(code, env, ["bundle", "build", "--study", STUDY, "--replications", "0"])
    manifest = json.loads((var / "bundles" / STUDY / "manifest.json").read_text())
    phases = manifest["built"]["phase_wall_time_s"]
    worlds = yaml.safe_load((configs_dir / f"{STUDY}.yaml").read_text())["worlds"]
    cells = len(worlds) * grid_size(configs_dir)
    checkpoints = 2 * len(worlds) * len(manifest["seeds"])
    pairs = sum(json.loads((var / "data" / world / "meta.json").read_text())["pairs"]["train"]
                for world in worlds)
    return {"wall": wall, "cpu": cpu, "phases": phases, "pairs": pairs,
            "per_file": phases["data"] / (files * len(worlds)),
            "per_cell": phases["selection"] / cells,
            "per_checkpoint": phases["training"] / checkpoints,
            "results": {"bank": manifest["bank_sha256"], "models": manifest["models"]}}


def grid_size(configs_dir: Path) -> int:
    """Selection cells per world: every Ours levels cell and every VAE cell of the grid."""
    from app.learning.select import grid_cells, load_selection_config

    return len(grid_cells(load_selection_config(configs_dir / "model_selection.yaml")))


COMMANDS = {"interaction": interaction_run, "bundle": bundle_run}
READS = {"interaction": (ROUNDABOUT,), "bundle": SCENARIOS}  # the scenarios each command reads


def scenarios_read(commands: list[str]) -> tuple[str, ...]:
    """The scenarios any of `commands` reads, in SCENARIOS order."""
    return tuple(s for s in SCENARIOS if any(s in READS[c] for c in commands))


def measure(code: Path, tag: str, counts: list[int], commands: list[str], source: Path,
            root: Path, seeds: int | None, max_epochs: int | None) -> dict:
    """Every command at every file count with one checkout: {(command, files): run}."""
    configs_dir = configs(code, root / tag / "configs", seeds, max_epochs)
    out = {}
    for files in counts:
        data = root / f"files_{files}" / "INTERACTION"  # one path for both checkouts: the
        if not data.exists():  # checkpoints name their input files
            first_files(source, files, data, scenarios_read(commands))
        for command in commands:
            var = root / tag / f"files_{files}" / f"var_{command}"
            out[(command, files)] = COMMANDS[command](code, data, var, configs_dir, files)
            print_row(tag, command, files, out[(command, files)])
    return out


def print_row(tag: str, command: str, files: int, row: dict) -> None:
    """One run's line of the table."""
    phases = ", ".join(f"{k} {v:.0f}" for k, v in row["phases"].items())
    flag = "" if row["wall"] < TARGET_S else "  (over 5 min)"
    print(f"{tag:8} {command:11} {files:5d} {row['pairs']:7d} {row['wall']:8.1f} {row['cpu']:8.1f} "
          f"{row['per_file']:8.2f} {row['per_cell']:8.1f} {row['per_checkpoint']:8.1f}   "
          f"{phases}{flag}", flush=True)


def print_growth(runs: dict, tag: str) -> None:
    """Each command's wall time per count relative to the smallest count's."""
    for command in {c for c, _ in runs}:
        counts = sorted(n for c, n in runs if c == command)
        base = runs[(command, counts[0])]["wall"]
        print(f"{tag} {command} growth (wall / wall at {counts[0]} file(s)): "
              + ", ".join(f"{n} files {runs[(command, n)]['wall'] / base:.2f}x" for n in counts))


def print_comparison(before: dict, after: dict) -> None:
    """Before/after ratios and whether the results are identical."""
    for key in sorted(after):
        old, new = before[key], after[key]
        differ = [k for k in new["results"] if json.dumps(old["results"].get(k), sort_keys=True)
                  != json.dumps(new["results"][k], sort_keys=True)]
        same = "yes" if not differ else "no, " + ", ".join(differ) + " differ"
        print(f"{key[0]} {key[1]} files: baseline/this {old['wall'] / new['wall']:.2f}x wall, "
              f"{old['cpu'] / new['cpu']:.2f}x CPU; " + ", ".join(
                  f"{k} {old['phases'][k] / max(v, 0.1):.2f}x" for k, v in new["phases"].items()
                  if k in old["phases"]) + f"; identical results: {same}")


def main() -> None:
    """Generate, time every command at every file count, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", default="1,2,4,6", help="file counts, comma-separated")
    parser.add_argument("--minutes", type=float, default=15.0, help="traffic per file")
    parser.add_argument("--arrivals-per-arm-min", type=float, default=None,
                        help="default: generate-recordings' real size (24)")
    parser.add_argument("--recordings", type=Path, default=None,
                        help="keep the generated files here and reuse them on the next run")
    parser.add_argument("--commands", default="interaction,bundle")
    parser.add_argument("--baseline-code", type=Path, default=None,
                        help="a checkout to run first on the same files (before/after)")
    parser.add_argument("--seeds", type=int, default=None, help="default: the configs'")
    parser.add_argument("--max-epochs", type=int, default=None, help="default: training.yaml's")
    args = parser.parse_args()
    counts = sorted(int(n) for n in args.files.split(","))
    commands = args.commands.split(",")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        source = args.recordings or root / "generated"
        generate(source.resolve(), max(counts), args.minutes, args.arrivals_per_arm_min,
                 scenarios_read(commands))
        print(f"GENERATED, NOT REAL files: {args.minutes:g} min each, both scenarios, "
              f"{os.cpu_count()} CPUs (times depend on the machine's load)")
        print(f"{'code':8} {'command':11} {'files':>5} {'pairs':>7} {'wall s':>8} {'CPU s':>8} "
              f"{'s/file':>8} {'s/cell':>8} {'s/ckpt':>8}   phases (s)")
        before = None
        if args.baseline_code:
            before = measure(args.baseline_code.resolve(), "baseline", counts, commands,
                             source.resolve(), root, args.seeds, args.max_epochs)
        after = measure(CODE, "this", counts, commands, source.resolve(), root, args.seeds,
                        args.max_epochs)
    if before:
        print_growth(before, "baseline")
    print_growth(after, "this")
    if before:
        print_comparison(before, after)
    print(f"total benchmark time {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
