"""A world's trajectory file, however the world gets it: simulated, or imported recordings."""

from collections.abc import Callable
from pathlib import Path

from app.layout import Layout
from app.worlds.registry import SimulatedWorld, build_world


def make_world_data(world: str, layout: Layout, n: int, seed: int,
                    say: Callable[[str], None] = print) -> Path:
    """Write data/<world>/trajectories.npz and meta.json: simulate `n` trajectories of a
    simulated world (seed `seed`), or import every recording of a recorded one."""
    built = build_world(world)
    if isinstance(built, SimulatedWorld):
        from app.worlds.simulate import simulate

        say(f"simulating {n} {world} trajectories")
        return simulate(world, n, seed, layout).npz_path
    say(f"importing the recordings of {world}")
    return built.import_recordings(layout).npz_path


def import_world_data(world: str, layout: Layout):
    """Import a recorded world's recordings (ConfigError for a simulated world)."""
    from app.configio import ConfigError

    built = build_world(world)
    if isinstance(built, SimulatedWorld):
        raise ConfigError(f"world: {world} is a simulated world; `tomstudy simulate {world}` "
                          "makes its data")
    return built.import_recordings(layout)
