"""A world's trajectory file, however the world gets it: simulated, or imported recordings."""

from collections.abc import Callable

from app.configio import ConfigError
from app.layout import Layout
from app.worlds.registry import build_world, is_recorded


def make_world_data(world: str, layout: Layout, n: int, seed: int,
                    say: Callable[[str], None] = print) -> None:
    """Write data/<world>/trajectories.npz and meta.json: simulate `n` trajectories of a
    simulated world (seed `seed`), or import every recording of a recorded one."""
    if is_recorded(world):
        say(f"importing the recordings of {world}")
        import_world_data(world, layout)
        return
    from app.worlds.simulate import simulate

    say(f"simulating {n} {world} trajectories")
    simulate(world, n, seed, layout)


def import_world_data(world: str, layout: Layout):
    """Import a recorded world's recordings (ConfigError for a simulated world)."""
    if not is_recorded(world):
        raise ConfigError(f"world: {world} is a simulated world; `tomstudy simulate {world}` "
                          "makes its data")
    return build_world(world).import_recordings(layout)
