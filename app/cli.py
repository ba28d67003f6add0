"""The `tomstudy` command line: each subcommand parses options and calls one function."""

import sys
from collections.abc import Iterable
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from pydantic import ValidationError

from app.configio import ConfigError
from app.settings import get_settings
from app.worlds.registry import simulated_world_names

if TYPE_CHECKING:
    from app.bank.served import SimulationInputs

# the help of every command taking a world; recorded worlds are whatever YAML says so
SIMULATED_HELP = f"a simulated world: {simulated_world_names()}"
WORLD_DATA_HELP = (f"{simulated_world_names()}, or a recorded world (kind: recorded); reads "
                   "var/data/<world>/")
# seconds a serve worker may take to answer uvicorn's supervisor before it is replaced
WORKER_HEALTHCHECK_S = 60
cli = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Worlds, models and the online study of how people predict a robot.")


@cli.callback()
def root() -> None:
    """Worlds, models and the online study of how people predict a robot."""


def fail(message: str, code: int = 2) -> None:
    """Print a CLI error to stderr and exit with `code` (2 = bad input)."""
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


@cli.command()
def simulate(
    world: Annotated[str, typer.Argument(help=SIMULATED_HELP)],
    n: Annotated[int, typer.Option("--n", min=1, help="trajectories to keep")] = 2000,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    config: Annotated[Path | None, typer.Option(help="world YAML (default: study_configs)")] = None,
    policy: Annotated[str, typer.Option(help="mpc, or sac (obstacle only)")] = "mpc",
    workers: Annotated[int | None, typer.Option(min=1, help="processes (default 2)")] = None,
    plot: Annotated[bool, typer.Option("--plot", help="also write a PNG of trajectories")] = False,
    if_missing: Annotated[bool, typer.Option("--if-missing", help="skip if data exists")] = False,
) -> None:
    """Simulate a world's two-agent trajectories into var/data/<world>/."""
    from app.worlds.simulate import simulate as run

    layout = get_settings().layout
    npz_path = layout.trajectories(world)
    if if_missing and npz_path.exists() and layout.trajectories_meta(world).exists():
        typer.echo(f"{npz_path} exists; skipping")
        return
    try:
        result = run(world, n, seed, layout, config, policy, workers)
    except ConfigError as err:
        fail(str(err))
    meta = result.meta
    typer.echo(f"wrote {result.npz_path} ({meta['n']} kept, {sum(meta['rejected'].values())} "
               f"rejected, {meta['wall_time_s']} s)")
    if plot:
        from app.worlds.plots import plot_simulated

        typer.echo(f"wrote {plot_simulated(layout, world, config, policy)}")


@cli.command("import-recordings")
def import_recordings_cmd(
    world: Annotated[str, typer.Argument(help="a recorded world: study_configs/worlds/<world>"
                                         ".yaml with kind: recorded")],
) -> None:
    """Read a recorded world's recordings into var/data/<world>/ (its `simulate`)."""
    from app.recordings.importer import RECORDING_ERRORS
    from app.worlds.world_data import import_world_data

    try:
        result = import_world_data(world, get_settings().layout)
    except RECORDING_ERRORS as err:
        fail(str(err))
    meta = result.meta
    typer.echo(f"wrote {result.npz_path} ({meta['pairs']['train']} training and "
               f"{meta['pairs']['held_out']} held-out pairs from {meta['source']})")


@cli.command("generate-recordings")
def generate_recordings_cmd(
    out: Annotated[Path | None, typer.Option(help="folder (default: <recordings dir>/"
                                             "INTERACTION, where the recorded worlds look)")]
    = None,
    seconds: Annotated[float, typer.Option(min=60, help="training traffic per scenario, "
                                           "half as much held out; with --files: traffic "
                                           "per file")] = 900.0,
    files: Annotated[int | None, typer.Option(min=1, help="real size: both scenarios in the "
                                              "v1.0 layout, this many recording files each "
                                              "(vehicle_tracks_000.csv, ...)")] = None,
    arrivals_per_arm_min: Annotated[float | None, typer.Option(
        min=0.1, max=59.9, help="cars arriving per arm per minute (default 12 at the "
        "roundabout, 8.6 at the intersection; with --files 24: about 30 cars in view, "
        "as on a real file)")] = None,
) -> None:
    """Write GENERATED, NOT REAL INTERACTION-format files of the interaction study's two
    scenarios (a v1.2 roundabout, a v1.0 intersection) for demos, tests and labs without data."""
    from app.recordings.generated import generate_study_recordings

    folder = out or get_settings().layout.recordings() / "INTERACTION"
    for summary in generate_study_recordings(folder, seconds, files, arrivals_per_arm_min):
        typer.echo(f"wrote {summary['scenario']} ({summary['layout']}) into {folder}: "
                   "GENERATED, NOT REAL DATA")


@cli.command()
def train(
    world: Annotated[str, typer.Option(help=WORLD_DATA_HELP)],
    model: Annotated[str, typer.Option(help="ours or vae")] = "ours",
    seed: Annotated[int, typer.Option(min=0)] = 0,
    config: Annotated[Path | None, typer.Option(help="training YAML (default: study_configs)")]
    = None,
    out: Annotated[Path | None, typer.Option(help="default var/models/<world>/<model>/seed<k>/")]
    = None,
    if_missing: Annotated[bool, typer.Option("--if-missing", help="skip if checkpoint exists")]
    = False,
    ours_checkpoint: Annotated[Path | None, typer.Option(
        help="VAE: the Ours checkpoint whose used codes set the k-means k "
             "(default var/models/<world>/ours/seed<k>/checkpoint.pt)")] = None,
) -> None:
    """Train Ours (FSQ autoencoder) or the VAE; writes checkpoint.pt, metrics.json, loss.png."""
    from app.layout import CHECKPOINT_FILE
    from app.learning.checkpoint import CheckpointError
    from app.learning.config import MODELS, load_train_config
    from app.learning.train import train_world

    if model not in MODELS:
        fail(f"--model: unknown model {model!r}; choose one of {', '.join(MODELS)}")
    layout = get_settings().layout
    target = (out or layout.model_dir(world, model, seed)) / CHECKPOINT_FILE
    if if_missing and target.exists():
        typer.echo(f"{target} exists; skipping")
        return
    try:
        path = train_world(layout, world, model, seed, load_train_config(config), out,
                           ours_checkpoint)
    except (FileNotFoundError, CheckpointError) as err:
        fail(str(err))
    typer.echo(f"wrote {path}")


@cli.command()
def sweep(
    world: Annotated[str, typer.Option(help=WORLD_DATA_HELP)],
    out: Annotated[Path | None, typer.Option(help="folder holding <world>/ (default "
                                             "var/models/sweep)")] = None,
    ceiling: Annotated[bool, typer.Option("--ceiling", help="only the supervised ceiling per "
                                          "robot label")] = False,
) -> None:
    """Exploratory sweep of Ours' FSQ levels, segment length and loss weights.

    It scores on test labels, so it never chooses a default: `tomstudy select` does that."""
    from app.learning.sweep import sweep_world

    try:
        sweep_world(get_settings().layout, world, out, ceiling, say=typer.echo)
    except FileNotFoundError as err:
        fail(str(err))


@cli.command("select")
def select_cmd(
    world: Annotated[str, typer.Option(help=WORLD_DATA_HELP)],
    config: Annotated[Path | None, typer.Option(help="selection YAML (default: "
                                                "study_configs/model_selection.yaml)")] = None,
    train_config: Annotated[Path | None, typer.Option(help="training YAML (default: "
                                                      "study_configs/training.yaml)")] = None,
    out: Annotated[Path | None, typer.Option(help="folder holding <world>/ (default "
                                             "var/models/selection)")] = None,
    workers: Annotated[int, typer.Option(min=1, help="processes the grid's cells train on "
                                         "(the choice does not depend on it)")] = 2,
) -> None:
    """Choose the VAE's beta_kl and latent size and Ours' FSQ levels on validation data.

    Prints the `selected:` block for study_configs/training.yaml."""
    from app.learning.select import select_world

    try:
        select_world(get_settings().layout, world, config, train_config, out, say=typer.echo,
                     workers=workers)
    except FileNotFoundError as err:
        fail(str(err))


@cli.command()
def fields(
    checkpoint: Annotated[Path, typer.Option(help="a checkpoint.pt from `tomstudy train`")],
    out: Annotated[Path | None, typer.Option(help="output dir (default: <checkpoint dir>/fields)")]
    = None,
    grid_n: Annotated[int, typer.Option(min=2, help="grid points per axis")] = 15,
) -> None:
    """Draw one vector field per used code (quiver PNGs over the scene) plus fields.json."""
    from app.learning.checkpoint import CheckpointError
    from app.learning.fields import write_fields

    try:
        paths = write_fields(checkpoint, out, grid_n)
    except CheckpointError as err:
        fail(str(err))
    for path in paths:
        typer.echo(f"wrote {path}")


@cli.command()
def pilot(
    url: Annotated[str, typer.Option(help="the study server")] = "http://127.0.0.1:8000",
    n: Annotated[int, typer.Option("--n", min=1, help="bots to run")] = 22,
    preset: Annotated[str, typer.Option("--kind", help="an observer preset: coarse, "
                                        "coarse_scene, coarse_momentum, coarse_relative, "
                                        "precise or random")] = "coarse",
    concurrency: Annotated[int, typer.Option(min=1, help="bots at once")] = 8,
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    seed: Annotated[int, typer.Option(min=0)] = 0,
    bank: Annotated[Path | None, typer.Option(help="trial bank (precise bots)")] = None,
) -> None:
    """Pilot the study: simulated participants take it through the real HTTP flow."""
    from app.bank.bundle import BundleError
    from app.bank.served import served_bank
    from app.pilot.bots import PRESETS, run_pilot

    if preset not in PRESETS:
        fail(f"kind: unknown bot kind {preset!r}; choose one of {', '.join(PRESETS)}")
    try:
        bank = bank or served_bank(get_settings(), study)
    except BundleError as err:
        fail(str(err))
    if preset == "precise" and not bank.is_file():
        fail(f"bank: {bank} not found (precise bots read the policy's moves from it)")
    failed = run_pilot(url, study, preset, n, concurrency, seed, bank)
    if failed:
        raise typer.Exit(1)


@cli.command()
def analyze(
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    out: Annotated[Path | None, typer.Option(help="report folder")] = None,
    csv: Annotated[Path | None, typer.Option(help="an exported CSV")] = None,
    database_url: Annotated[str | None, typer.Option(help="read the database instead")] = None,
    waive: Annotated[list[str] | None, typer.Option(help="switch off an exclusion rule "
                                                    "(sensitivity analysis; repeatable)")] = None,
) -> None:
    """Alignment error, paired tests, figures and a self-contained report."""
    from analysis.report import AnalysisError, run_analyze
    from app.bank.served import analysis_inputs

    if csv is not None and database_url is not None:
        fail("give either --csv or --database-url, not both")
    if csv is not None and not csv.is_file():
        fail(f"csv: {csv} not found")
    settings = get_settings()
    out = out or settings.layout.report_dir(study)
    try:
        run_analyze(study, out, csv, database_url or settings.resolved_database_url(),
                    analysis_inputs(settings, study, warn=warn), tuple(waive or ()))
    except AnalysisError as err:
        fail(str(err))


def warn(message: str) -> None:
    """Print a warning to stderr; the command goes on."""
    typer.echo(f"warning: {message}", err=True)


@cli.command()
def power(
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    preset: Annotated[str, typer.Option("--kind", help="an observer preset: coarse, "
                                        "coarse_scene, coarse_momentum, coarse_relative, "
                                        "precise or random")] = "coarse",
    n_max: Annotated[int, typer.Option("--n-max", min=3, help="largest n")] = 60,
    pool: Annotated[int, typer.Option(min=3, help="simulated participants")] = 400,
    reps: Annotated[int, typer.Option(min=10, help="resampled studies per n")] = 2000,
    alpha: Annotated[float, typer.Option(min=0, max=1)] = 0.01,
    out: Annotated[Path | None, typer.Option(help="output folder")] = None,
    seed: Annotated[int, typer.Option(min=0)] = 0,
) -> None:
    """Power to detect Ours < VAE vs n, from bots run in process on the trial bank: with
    participants random (seed 0, one-sided paired t) and, for an observer of the family, with
    participants and trials random (the primary test: family, min F'; power.csv
    power_trials_random)."""
    from app.observers.inverse_planning import PRESETS
    from app.observers.simulated_study import run_power

    if preset not in PRESETS:
        fail(f"kind: unknown bot kind {preset!r}; choose one of {', '.join(PRESETS)}")
    inputs = study_simulation(study)
    out = out or get_settings().layout.power_report(study, preset)
    summary = run_power(inputs.bank, preset, inputs.trials_per_world, out, n_max, pool, reps,
                        alpha, seed, inputs.observers)
    random_trials = summary["n_for_power_0.8_trials_random"]
    for world, needed in summary["n_for_power_0.8"].items():
        typer.echo(f"{world}: d_z = {summary['d_z'][world]:.3f}, n for power 0.8 = {needed} "
                   f"(participants random, one-sided paired t); {random_trials[world]} "
                   f"(participants and trials random: the primary test, family, min F')")
    typer.echo(f"wrote {out}")


@cli.command()
def prereg(
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    out: Annotated[Path | None, typer.Option(help="output folder (default "
                                             "var/reports/prereg-<study>/)")] = None,
) -> None:
    """Write the study's preregistration (OSF template's sections) as Markdown and a
    self-contained HTML page, from its config, frozen bundle, instrument and power results."""
    from app.bank.bundle import BundleError
    from app.prereg.write import write_prereg

    settings = get_settings()
    try:
        paths = write_prereg(settings, study, out or settings.layout.prereg_report(study))
    except (ConfigError, BundleError) as err:
        fail(f"--study: {study}: {err}")
    for path in paths:
        typer.echo(f"wrote {path}")


def study_simulation(study: str, observers: Path | None = None,
                     bank: Path | None = None) -> "SimulationInputs":
    """What simulated participants of `study` run on; exit 2 naming what is missing."""
    from app.bank.bundle import BundleError
    from app.bank.served import simulation_inputs

    if bank is not None and not bank.is_file():
        fail(f"--bank: {bank} not found")
    try:
        return simulation_inputs(get_settings(), study, observers, bank)
    except (BundleError, ConfigError) as err:
        fail(str(err))


@cli.command("check-display")
def check_display_cmd(
    study: Annotated[str, typer.Option(help="study id (reads its bank and the worlds' data)")]
    = "paper_study",
) -> None:
    """Can a person click the robot's true moves, and is a behaviour one direction?"""
    from app.bank.bundle import BundleError
    from app.bank.display_check import check_display, format_table
    from app.bank.served import served_bank

    settings = get_settings()
    try:
        result = check_display(settings.layout, study, served_bank(settings, study))
    except (FileNotFoundError, BundleError) as err:
        fail(str(err))
    typer.echo(format_table(result))


@cli.command()
def instrument(
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    n: Annotated[int, typer.Option("--n", min=2, help="participants per population")] = 22,
    alpha: Annotated[float, typer.Option(min=0, max=1)] = 0.01,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    observers: Annotated[Path | None, typer.Option(help="observers YAML (default: "
                                                   "study_configs/observers.yaml)")] = None,
    out: Annotated[Path | None, typer.Option(help="output folder")] = None,
    replications: Annotated[int, typer.Option(min=0, help="reruns with fresh simulated "
                                              "participants, for the pass rate")] = 50,
    grid: Annotated[bool, typer.Option(help="also run every seed pair x click-noise level "
                                       "(app/observers/instrument_grid.py)")] = True,
    bank: Annotated[Path | None, typer.Option(help="a bank file (default: the bank of the "
                                              "bundle the study is served from)")] = None,
    goal_reps: Annotated[int, typer.Option(min=20, help="simulated studies per design-goal "
                                           "cell")] = 400,
    search: Annotated[bool, typer.Option(help="also search the participants and bank trials "
                                         "that would meet the design goal")] = True,
) -> None:
    """Instrument check: can err_ours - err_vae tell coarse from precise simulated observers?

    Simulates n coarse and n precise participants in process on the study's trial bank and,
    per world, runs Welch's one-sided t-test that the coarse population's per-participant
    err_ours - err_vae is lower than the precise one's (pass at p < alpha); the relative lane
    reading (coarse_relative) is a sensitivity row. The pass rate is the share of
    `replications` reruns (fresh participants) that pass: the check's power. Writes
    instrument.json, CSVs and by_trial.png (where the contrast is).

    Then the design goal (the sufficient test): at the study's planned design, with
    participants and trials random, P(the primary test concludes Ours) for every observer of
    the family: >= 0.8 for every coarse one, <= alpha for the precise one; goal.{json,csv}.
    Exits 1 if a world that is not marked exploratory misses it.
    """
    from app.observers.instrument_tables import instrument_table, separation_table
    from app.observers.simulated_study import run_instrument

    inputs = study_simulation(study, observers, bank)
    out = out or get_settings().layout.instrument_report(study)
    summary = run_instrument(inputs.bank, inputs.trials_per_world, out, n, seed, alpha,
                             inputs.observers, replications)
    echo_lines(instrument_table(summary, alpha, replications))
    echo_lines(separation_table(summary["separation"]))
    if grid:
        from app.observers.instrument_grid import grid_table, run_instrument_grid

        echo_lines(grid_table(run_instrument_grid(inputs.bank, inputs.trials_per_world, out,
                                                  inputs.observers, n, seed, alpha,
                                                  replications)))
    missed = design_goal(study, inputs, out, alpha, goal_reps, search, seed)
    typer.echo(f"wrote {out}")
    if missed:
        raise typer.Exit(1)


def design_goal(study: str, inputs, out: Path, alpha: float, reps: int, search: bool,
                seed: int) -> list[str]:
    """Run, print and write the design goal (app/observers/design_goal.py); the worlds that
    miss it and are not marked exploratory."""
    from app.observers.design_goal import Design, run_goal_report
    from app.observers.instrument_tables import goal_table
    from app.study.config import held_out_seeds, load_study_config

    config = load_study_config(get_settings(), study)
    design = Design(config.target_sample_size, config.bank_trials_per_world,
                    config.trials_per_world)
    result = run_goal_report(inputs.bank, design, inputs.observers, held_out_seeds(config),
                             config.exploratory_worlds, out, alpha, reps, search, seed)
    echo_lines(goal_table(result, config.exploratory_worlds))
    return [w for w, met in result["goal_met"].items()
            if not met and w not in config.exploratory_worlds]


def echo_lines(lines: Iterable[str]) -> None:
    """Print each line."""
    for line in lines:
        typer.echo(line)


bundle_cli = typer.Typer(no_args_is_help=True,
                         help="A study's frozen bundle: its bank, checkpoints and configs.")
cli.add_typer(bundle_cli, name="bundle")


@bundle_cli.command("build")
def bundle_build(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
    workers: Annotated[int, typer.Option(min=1, help="training processes")] = 2,
    replace_shipped: Annotated[bool, typer.Option(
        "--replace-shipped", help="then copy it over the bundle that ships in the configs "
        "dir (maintainers: commit it with the numbers it changes)")] = False,
    replications: Annotated[int, typer.Option(min=0, help="instrument reruns per bank when "
                                              "comparing with the shipped bundle")] = 20,
) -> None:
    """Simulate, train every seed and build the bank where missing, freeze the bundle into
    var/bundles/<study>/, and report how it differs from the shipped one."""
    from app.bank.bundle import BundleError
    from app.bank.bundle_diff import compare_with_shipped
    from app.bank.prepare import build_bundle
    from app.bank.prepare import replace_shipped as replace

    settings = get_settings()
    try:
        built = build_bundle(settings, study, workers, say=typer.echo)
    except (FileNotFoundError, ValueError, BundleError) as err:
        fail(str(err))
    try:
        echo_lines(compare_with_shipped(settings, study, built, replications))
    except BundleError as err:
        typer.echo(f"the shipped bundle cannot be compared: {err}")
    if replace_shipped:
        typer.echo(f"replaced {replace(built, settings.configs_dir, study)}")


@bundle_cli.command("verify")
def bundle_verify(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
    bundle: Annotated[Path | None, typer.Option(help="a bundle folder (default: the one the "
                                                "study is served from)")] = None,
) -> None:
    """Check every file against the manifest and recompute every stored answer (every
    checkpoint's and plug-in predictor's) on this machine; print the largest differences, then
    each checkpoint's training epochs and whether it converged; exit 1 if any answer is beyond
    tolerance or a plug-in is not installed."""
    from app.bank.bundle import BundleError
    from app.bank.model_answers import agreement_lines, recompute
    from app.bank.served import served_bundle
    from app.bank.training_report import checkpoint_stopping, stopping_lines
    from app.bank.verify import open_bundle

    try:
        opened = open_bundle(bundle) if bundle else served_bundle(get_settings(), study)
    except BundleError as err:
        fail(str(err))
    files = opened.manifest["files"]
    typer.echo(f"{opened.root}: {len(files)} files, {sum(f['bytes'] for f in files.values())} "
               f"bytes, every SHA-256 as in the manifest; bank {opened.bank.sha256[:12]}")
    _, checks = recompute(opened.bank, opened.predictor)
    echo_lines(agreement_lines(checks, opened.plugins))
    echo_lines(stopping_lines(checkpoint_stopping(opened.root, opened.manifest["models"])))
    if not all(c.ok for c in checks):
        raise typer.Exit(1)


@cli.command()
def estimate(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
    wpm: Annotated[float, typer.Option(help="median participant's reading speed, words/min",
                                       min=1)] = 230.0,
    click_s: Annotated[float, typer.Option(help="median participant's seconds per click",
                                           min=0)] = 2.5,
    slow_wpm: Annotated[float, typer.Option(help="slow participant's words/min", min=1)] = 180.0,
    slow_click_s: Annotated[float, typer.Option(help="slow participant's seconds per click",
                                                min=0)] = 4.0,
) -> None:
    """How long the study takes (clips from its bank at the page's playback time, reading,
    clicking, the survey) for a median and a slow participant, the time it advertises and the
    pay at recruitment.hourly_pay."""
    from dataclasses import replace

    from app.bank.bundle import BundleError
    from app.bank.served import served_bundle
    from app.study.config import load_study_config
    from app.study.consent import consent_problem
    from app.study.estimate import (
        MEDIAN_PACE,
        SLOW_PACE,
        estimate_lines,
        player_timing,
        study_estimate,
    )

    settings = get_settings()
    config = load_study_config(settings, study)
    try:
        bank = served_bundle(settings, study).bank
    except BundleError as err:
        fail(str(err))
    timing = player_timing()
    median = replace(MEDIAN_PACE, words_per_minute=wpm, seconds_per_click=click_s)
    slow = replace(SLOW_PACE, words_per_minute=slow_wpm, seconds_per_click=slow_click_s)
    echo_lines(estimate_lines(study, study_estimate(config, bank, timing, median, slow), timing))
    problem = consent_problem(config, production=True)
    if problem:
        warn(f"a production server refuses this study: {problem}")


@cli.command("build-trials")
def build_trials_cmd(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
) -> None:
    """Build the study's trial bank from held-out trajectories into var/trials/<study>/."""
    from app.bank.build import build_trials
    from app.learning.checkpoint import CheckpointError
    from app.study.config import load_study_config

    settings = get_settings()
    try:
        path = build_trials(load_study_config(settings, study), study, settings.layout)
    except (FileNotFoundError, CheckpointError, ValueError) as err:
        fail(str(err))
    typer.echo(f"wrote {path}")


@cli.command()
def serve(
    host: Annotated[str, typer.Option(help="interface to listen on")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535)] = 8000,
    workers: Annotated[int, typer.Option(min=1, help="uvicorn worker processes")] = 1,
    study: Annotated[str | None, typer.Option(help="study id(s), comma-separated (default "
                                              "paper_study; with --archive, its study)")]
    = None,
    prepare: Annotated[bool, typer.Option("--prepare", help="first simulate, train and "
                                          "build-trials whatever is missing")] = False,
    allow_bank_change: Annotated[bool, typer.Option(
        "--allow-bank-change", help="serve although sessions ran another trial bank")] = False,
    archive: Annotated[Path | None, typer.Option(
        help="serve the study of this archive (`tomstudy archive`) from its own bundle, on a "
             "fresh SQLite database; the lab's data dir and database are never read")] = None,
    archive_dir: Annotated[Path | None, typer.Option(
        help="with --archive: a new or empty folder for its configs, data and database "
             "(default: a temporary folder, removed when the server stops)")] = None,
) -> None:
    """Serve the study (participant app, API, researcher dashboard) with uvicorn."""
    import uvicorn

    from app.http.preflight import NotServable, forwarded_allow_ips, hand_to_workers
    from app.main import ready_to_serve

    with ExitStack() as cleanup:
        if archive is not None:
            study = archived_study(archive, archive_dir, study, prepare, cleanup)
        elif archive_dir is not None:
            fail("--archive-dir: only with --archive")
        study_ids = (study or "paper_study").split(",")
        try:
            settings = ready_to_serve(get_settings(), host, workers, study_ids,
                                      allow_bank_change, prepare, say=typer.echo)
        except NotServable as err:
            fail(str(err))
        hand_to_workers(settings, study_ids)
        docs = "off in production" if settings.production else "/docs"
        proxies = forwarded_allow_ips(settings)
        typer.echo(f"serving http://{host}:{port}/s/{study_ids[0]}  "
                   f"(researcher dashboard: /researcher, API docs: {docs}; client addresses "
                   f"from X-Forwarded-For of {proxies} only)")
        # info: each worker's start, and the supervisor replacing one that died; no access
        # log (as before: request lines and client addresses stay out of the log)
        # a worker answers the supervisor's health check only once it has re-imported this
        # CLI (spawn), about 1 s of CPU: on a loaded machine that passed uvicorn's default 5 s,
        # and the supervisor killed and replaced every worker before it could serve
        uvicorn.run("app.main:app_from_env", factory=True, host=host, port=port,
                    workers=workers, log_level="info", access_log=False,
                    proxy_headers=True, forwarded_allow_ips=proxies,
                    timeout_worker_healthcheck=WORKER_HEALTHCHECK_S,
                    timeout_keep_alive=settings.keep_alive_s)


def archived_study(archive: Path, archive_dir: Path | None, study: str | None, prepare: bool,
                   cleanup: ExitStack) -> str:
    """Point this process (and its workers) at a fresh folder holding the archive's study,
    set up from the verified archive; its study id. Exit 2 naming what is wrong."""
    import os
    import tempfile

    from app.researcher.reproduce import (
        LAB_ONLY_VARIABLES,
        ArchiveError,
        serving_environment,
        unpack_for_serving,
    )

    if prepare:
        fail("--prepare: an archive's bundle is served as it is; leave --prepare out")
    root = archive_dir or Path(cleanup.enter_context(
        tempfile.TemporaryDirectory(prefix="tomstudy-serve-archive-")))
    try:
        os.environ.update(serving_environment(root))
        for name in LAB_ONLY_VARIABLES:
            os.environ.pop(name, None)
        get_settings.cache_clear()
        archived = unpack_for_serving(archive, get_settings())
    except ArchiveError as err:
        fail(str(err))
    if study not in (None, archived):
        fail(f"--study: the archive holds study {archived!r}, not {study!r}")
    typer.echo(f"serving {archive}'s study {archived} from its own bundle; its configs, data "
               f"and a fresh SQLite database are in {root}")
    return archived


db_cli = typer.Typer(no_args_is_help=True,
                     help="The study database's schema revision (reads DATABASE_URL).")
cli.add_typer(db_cli, name="db")


@db_cli.command("upgrade")
def db_upgrade() -> None:
    """Bring the database to this tomstudy's schema revision, keeping every row."""
    from app.server.storage.db import make_engine
    from app.server.storage.migrate import SchemaError, upgrade, upgrade_lines, where

    engine = make_engine(get_settings().resolved_database_url())
    try:
        report = upgrade(engine)
    except SchemaError as err:
        fail(str(err))
    finally:
        engine.dispose()
    for line in upgrade_lines(report, where(engine)):
        typer.echo(line)


@db_cli.command("current")
def db_current() -> None:
    """Print the database's schema revision and this tomstudy's newest."""
    from app.server.storage.db import make_engine
    from app.server.storage.migrate import revision_lines

    engine = make_engine(get_settings().resolved_database_url())
    try:
        lines = revision_lines(engine)
    finally:
        engine.dispose()
    typer.echo("\n".join(lines))


@cli.command("preview-link")
def preview_link_cmd(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
    base_url: Annotated[str, typer.Option(help="where the study is served")] = "",
) -> None:
    """Print the study's researcher preview link: its sessions are pilots that never count."""
    from app.server.flow.recruitment import preview_key, preview_path

    token = get_settings().admin_token
    if not token.strip():
        fail("TOMSTUDY_ADMIN_TOKEN: not set; the preview link is derived from the researcher "
             "token of the running server (serve prints the one it made)")
    key = preview_key(token, study)
    typer.echo(base_url.rstrip("/") + preview_path(study, key))


@cli.command("codes")
def codes_cmd(
    study: Annotated[str, typer.Option(help="study_configs/<study>.yaml")] = "paper_study",
) -> None:
    """Print each ending's completion code and its Prolific action (generated ones are made
    and kept in the data dir on first use)."""
    from app.configio import ConfigError
    from app.server.flow.completion_codes import codes_table, served_config
    from app.study.config import load_study_config

    settings = get_settings()
    try:
        config = served_config(load_study_config(settings, study), settings.layout, study)
    except (ConfigError, OSError, ValueError) as err:
        fail(str(err))
    source = ("generated, kept in " + str(settings.layout.completion_codes(study))
              if config.recruitment.codes == "generated" else "pinned in the study config")
    typer.echo(f"{study}: completion codes ({source})")
    for row in codes_table(config):
        typer.echo(f"  {row['ending']:<17} {row['completion_code'] or '(none)':<12} "
                   f"Prolific: {row['prolific_action']}")


@cli.command("export")
def export_cmd(
    study: Annotated[str, typer.Option(help="study id")] = "paper_study",
    what: Annotated[str, typer.Option(help="predictions, survey, events or participants")]
    = "predictions",
    out: Annotated[Path | None, typer.Option(help="CSV file (default: stdout); its codebook "
                                             "goes beside it as FILE.datapackage.json")] = None,
) -> None:
    """Write one of the study's exports as CSV, read from DATABASE_URL, and with --out its
    codebook (a Frictionless Data Package) beside it."""
    from sqlmodel import Session

    from app.core.contracts import WHAT
    from app.core.csvsafe import write_csv
    from app.researcher.exports import export_table

    if what not in WHAT:
        fail(f"--what: unknown export {what!r}; choose one of {', '.join(WHAT)}")
    if out is not None:
        writable_target(out)
    config, engine = study_database(study)
    try:
        with Session(engine) as db:
            frame = export_table(db, config, study, what)
    finally:
        engine.dispose()
    try:
        write_csv(frame, out if out is not None else sys.stdout)
    except OSError as err:
        fail(f"--out: cannot write {out}: {err.strerror or err}")
    if out is None:
        typer.echo("no codebook on stdout: give --out FILE.csv to write FILE.datapackage.json "
                   "beside it (or GET /api/researcher/export/" + what + ".datapackage.json)",
                   err=True)
        return
    package = write_package_beside(frame, config, study, what, out)
    typer.echo(f"wrote {out} ({len(frame)} rows) and its codebook {package}", err=True)


def write_package_beside(frame, config, study: str, what: str, out: Path) -> Path:
    """Write the data package of the export CSV `out` beside it; returns its path."""
    from app.researcher.exports import package_path, write_export_package

    try:
        return write_export_package(frame, config, study, what, out)
    except OSError as err:
        fail(f"--out: cannot write {package_path(out)}: {err.strerror or err}")


def writable_target(out: Path, kind: str = "CSV") -> None:
    """Make `out`'s folder where missing; a one-line CLI error where it cannot be a file."""
    if out.is_dir():
        fail(f"--out: {out} is a folder; give a {kind} file name")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        fail(f"--out: cannot make the folder {out.parent}: {err.strerror or err}")


@cli.command()
def withdraw(
    study: Annotated[str, typer.Option(help="study id")],
    external_id: Annotated[str | None, typer.Option("--external-id", help="the participant's "
                                                    "platform id (PROLIFIC_PID, workerId)")]
    = None,
    participant_id: Annotated[str | None, typer.Option(
        "--participant-id", help="a session's public id (open and pilot sessions)")] = None,
) -> None:
    """Delete every row of one participant (all sessions, one transaction); print the audit
    line and the archives (`tomstudy archive`) that hold them, to re-issue."""
    import json

    from app.researcher.archive_registry import RegistryError
    from app.researcher.withdrawal import withdraw_and_erase
    from app.server.schemas import WithdrawalByExternalId, WithdrawalByParticipantId
    from app.study.errors import Refused

    if (external_id is None) == (participant_id is None):
        fail("give exactly one of --external-id and --participant-id")
    who = (WithdrawalByExternalId(study_id=study, external_id=external_id)
           if external_id is not None else
           WithdrawalByParticipantId(study_id=study, participant_id=participant_id))
    config, engine = study_database(study)
    try:
        line = withdraw_and_erase(engine, study, who, config.recruitment.platform, via="cli",
                                  layout=get_settings().layout)
    except Refused as err:
        kind = err.detail.split(":", 1)[0]
        fail(err.detail.replace(f"{kind}:", f"--{kind.replace('_', '-')}:", 1), 1)
    except RegistryError as err:
        fail(str(err), 1)
    finally:
        engine.dispose()
    typer.echo(json.dumps(line))
    for archive in line["archives"]:
        warn(f"{archive['path']} (written {archive['created_at']}) holds this participant: "
             "re-issue it without them (`tomstudy archive`) and withdraw the old copy")


@cli.command()
def archive(
    study: Annotated[str, typer.Option(help="study id")],
    out: Annotated[Path, typer.Option(help="the archive to write (.zip)")],
    with_free_text: Annotated[bool, typer.Option(
        "--with-free-text", help="also the survey's free-text answers (left out by default: "
                                 "people may write what identifies them)")] = False,
) -> None:
    """Write one zip for a reviewer: the study's bundle and config, its exports (pseudonymous,
    read from DATABASE_URL), the analysis of them, the environment and ARCHIVE.json with every
    member's SHA-256 and the participants it holds (entered in the data dir's registry)."""
    from analysis.report import AnalysisError
    from app.bank.bundle import BundleError
    from app.researcher.archive import ArchiveJob, write_archive
    from app.researcher.archive_registry import RegistryError

    if out.suffix != ".zip":
        fail(f"--out: {out} must end in .zip")
    writable_target(out, "zip")
    config, engine = study_database(study)
    try:
        entry = write_archive(ArchiveJob(get_settings(), study, engine, config, with_free_text),
                              out)
    except (AnalysisError, BundleError, RegistryError, OSError) as err:
        fail(str(err))
    finally:
        engine.dispose()
    typer.echo(f"wrote {out} ({out.stat().st_size} bytes, SHA-256 {entry['sha256']}; "
               f"{len(entry['participant_ids'])} participants; registered in "
               f"{get_settings().layout.archive_registry()})")


@cli.command()
def reproduce(
    archive: Annotated[Path, typer.Argument(help="an archive of `tomstudy archive`")],
) -> None:
    """Check every member's SHA-256, re-run the archived analysis here and print every number
    beside its recomputation; exit 1 if a member is altered or a number differs."""
    import tempfile

    from analysis.report import AnalysisError
    from app.bank.bundle import BundleError
    from app.researcher.reproduce import ArchiveError
    from app.researcher.reproduce import reproduce as run_reproduce

    if not archive.is_file():
        fail(f"ARCHIVE: {archive} not found")
    with tempfile.TemporaryDirectory(prefix="tomstudy-reproduce-") as work:
        try:
            agreed = run_reproduce(archive, Path(work), say=typer.echo)
        except (ArchiveError, AnalysisError, BundleError, ConfigError) as err:
            fail(str(err), 1)
    if not agreed:
        raise typer.Exit(1)


prolific_cli = typer.Typer(no_args_is_help=True, help="Prolific's API for a study's sessions "
                          "(reads DATABASE_URL and TOMSTUDY_PROLIFIC_TOKEN_FILE).")
cli.add_typer(prolific_cli, name="prolific")
StudyOption = Annotated[str, typer.Option(help="study id")]
PublicIds = Annotated[list[str], typer.Argument(help="sessions' participant_id (the payment "
                                                    "sheet's column)")]


@prolific_cli.command("approve")
def prolific_approve(participant_ids: PublicIds, study: StudyOption) -> None:
    """Approve (pay) these completed sessions' Prolific submissions; print the audit lines."""
    _payment_action(study, "approve", participant_ids, None)


@prolific_cli.command("return")
def prolific_return(
    participant_ids: PublicIds, study: StudyOption,
    reason: Annotated[str, typer.Option(help="what Prolific tells the participant, e.g. "
                                             "\"Didn't finish the study\"")],
) -> None:
    """Ask these sessions' participants to return their submissions; print the audit lines."""
    _payment_action(study, "return", participant_ids, reason)


def _payment_action(study: str, action: str, participant_ids: list[str],
                    reason: str | None) -> None:
    import asyncio
    import json

    from app.researcher.payments import send_actions
    from app.server.prolific import client_from
    from app.study.errors import Refused

    _, engine = study_database(study)
    try:
        lines = asyncio.run(send_actions(engine, client_from(get_settings()), study, action,
                                         participant_ids, reason, via="cli"))
    except Refused as err:
        fail(err.detail.replace("participant_ids:", "PARTICIPANT_IDS:", 1)
             .replace("reason:", "--reason:", 1), 1)
    finally:
        engine.dispose()
    for line in lines:
        typer.echo(json.dumps(line))
    if not all(line["ok"] for line in lines):
        raise typer.Exit(1)


@prolific_cli.command("recheck")
def prolific_recheck(study: StudyOption) -> None:
    """Ask Prolific again about the sessions it could not be asked about at their start."""
    import asyncio

    from app.server.flow.prolific_check import recheck_pending
    from app.server.prolific import client_from

    client = client_from(get_settings())
    if client is None:
        fail("TOMSTUDY_PROLIFIC_TOKEN_FILE: not set; without a token nothing is asked")
    config, engine = study_database(study)
    try:
        tally = asyncio.run(recheck_pending(engine, client, study, config, limit=10_000))
    finally:
        engine.dispose()
    typer.echo(", ".join(f"{n} {verdict}" for verdict, n in tally.items()))


def study_database(study: str):
    """(study config, engine on DATABASE_URL) for a study's stored data; exit 2 naming the
    option or variable to fix."""
    from app.server.storage.db import NoDatabase, open_existing
    from app.server.storage.migrate import SchemaError
    from app.study.config import load_study_config

    settings = get_settings()
    try:
        config = load_study_config(settings, study)
    except ConfigError as err:
        fail(f"--study: unknown study {study!r} ({err})")
    try:
        return config, open_existing(settings.resolved_database_url())
    except (NoDatabase, SchemaError) as err:
        fail(str(err))


@cli.command()
def interaction(
    data: Annotated[Path, typer.Option(help="folder with the INTERACTION files (v1.0 or v1.2)")],
    scenario: Annotated[str, typer.Option(help="e.g. DR_USA_Roundabout_FT")],
    seeds: Annotated[int | None, typer.Option(min=2, help="training seeds (default 10)")] = None,
    max_epochs: Annotated[int | None, typer.Option(min=1, help="cap training epochs")] = None,
    config: Annotated[Path | None, typer.Option(help="experiment YAML (keys of "
                                                "InteractionConfig)")] = None,
    train_config: Annotated[Path | None, typer.Option(help="training YAML")] = None,
    generate: Annotated[str | None, typer.Option(help="first write GENERATED files in this "
                                                 "layout (v1.0 or v1.2) into --data")] = None,
    frame_seeds: Annotated[int | None, typer.Option(min=0, help="seeds of the human-relative "
                                                    "frame row (0 skips it; default 5)")] = None,
    workers: Annotated[int, typer.Option(min=1, help="training processes (1: one after "
                                         "another in this process)")] = 2,
) -> None:
    """Ours vs VAE vs constant velocity on INTERACTION pairs; report in var/reports/interaction/."""
    from app.interaction.dataset import InteractionError
    from app.interaction.experiment import run_command
    from app.interaction.report import frame_verdict, verdict
    from app.recordings.lanelet_map import MapError
    from app.recordings.tracks import TrackFileError

    try:
        if generate:
            from app.recordings.synthetic_tracks import generate as write_generated

            write_generated(data, scenario, generate)
        summary = run_command(data, scenario, get_settings().layout, config, train_config,
                              seeds, max_epochs, frame_seeds=frame_seeds, workers=workers)
    except (TrackFileError, InteractionError, MapError, ValueError) as err:
        fail(str(err))
    out = get_settings().layout.interaction_report(scenario)
    typer.echo(verdict(summary))
    if frame_verdict(summary):
        typer.echo(frame_verdict(summary))
    typer.echo(f"wrote {out / 'report.html'} and {out / 'summary.json'}")


def main() -> None:
    """Console-script entry point."""
    try:
        cli()
    except ConfigError as err:  # any command's config problem is a usage error
        typer.echo(f"error: {err}", err=True)
        sys.exit(2)
    except ValidationError as err:  # the settings (environment) are unusable
        problems = "; ".join(e["msg"].removeprefix("Value error, ") for e in err.errors())
        typer.echo(f"error: {problems}", err=True)
        sys.exit(2)


# `python -m app.cli` runs this checkout's code (the console script runs the installed one)
if __name__ == "__main__":
    main()
