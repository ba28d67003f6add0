"""The `tomstudy` command line: each subcommand parses options and calls one function."""

import sys
from pathlib import Path
from typing import Annotated

import typer

from app.configio import ConfigError
from app.settings import get_settings

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
    world: Annotated[str, typer.Argument(help="highway or obstacle")],
    n: Annotated[int, typer.Option("--n", min=1, help="trajectories to keep")] = 2000,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    config: Annotated[Path | None, typer.Option(help="world YAML (default: study_configs)")] = None,
    policy: Annotated[str, typer.Option(help="mpc, or sac (obstacle only)")] = "mpc",
    workers: Annotated[int | None, typer.Option(min=1, help="processes (default 2)")] = None,
    plot: Annotated[bool, typer.Option("--plot", help="also write a PNG of trajectories")] = False,
    if_missing: Annotated[bool, typer.Option("--if-missing", help="skip if data exists")] = False,
) -> None:
    """Simulate a world's two-agent trajectories into var/data/<world>/."""
    from app.worlds.simulate import output_paths
    from app.worlds.simulate import simulate as run

    data_dir = get_settings().data_dir
    npz_path, meta_path = output_paths(data_dir, world)
    if if_missing and npz_path.exists() and meta_path.exists():
        typer.echo(f"{npz_path} exists; skipping")
        return
    try:
        result = run(world, n, seed, data_dir, config, policy, workers)
    except ConfigError as err:
        fail(str(err))
    meta = result.meta
    typer.echo(f"wrote {result.npz_path} ({meta['n']} kept, {sum(meta['rejected'].values())} "
               f"rejected, {meta['wall_time_s']} s)")
    if plot:
        from app.data.trajectory import TrajectorySet
        from app.worlds.plots import plot_trajectories
        from app.worlds.registry import build_world

        label = build_world(world, config, policy).robot_label
        png = plot_trajectories(TrajectorySet.load(result.npz_path),
                                result.npz_path.with_name("trajectories.png"), label)
        typer.echo(f"wrote {png}")


def main() -> None:
    """Console-script entry point."""
    try:
        cli()
    except ConfigError as err:  # any command's config problem is a usage error
        typer.echo(f"error: {err}", err=True)
        sys.exit(2)
