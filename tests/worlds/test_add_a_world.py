"""docs/extend/add-a-world.md, followed: a third simulated world built from the guide's own code
blocks only, simulated, trained, banked and served through the entry points it names.

The guide's module goes into a scratch folder that joins the `app.worlds` package for the
test, its registry entry into `SIMULATED_WORLDS` for the test; both are gone afterwards.
"""

import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import app.worlds
from app.cli import cli
from app.configio import ConfigError
from app.data.trajectory import TrajectorySet
from app.worlds import registry
from tests.conftest import SMALL_STUDY_OVERRIDES, SmallStudy, settings_of, write_small_configs
from tests.server.flow import at_first_trial, make_client

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "extend" / "add-a-world.md"
WORLD, STUDY = "corridor", "corridor_study"
MODULE = f"app.worlds.{WORLD}"
FENCED = re.compile(r"^(?P<intro>[^\n]*)\n\n```(?P<lang>\w+)\n(?P<code>.*?)^```$",
                    re.MULTILINE | re.DOTALL)
# the guide's `selected:` block, as `tomstudy select` would print it; small models
ONE_SEED = {"models": {"seeds": [0]}}  # one Ours and one VAE to train, not the small study's 4
SELECTED = {WORLD: {"levels": [3, 3], "beta_kl": 0.01, "vae_latent_dim": 2}}


def guide_blocks() -> dict[str, str]:
    """Each fenced block of the guide by the sentence it follows (ending in ':')."""
    return {m["intro"]: m["code"] for m in FENCED.finditer(GUIDE.read_text())
            if m["intro"].endswith(":")}


def block_after(blocks: dict[str, str], ending: str) -> str:
    """The one block whose introducing sentence ends with `ending`."""
    found = [code for intro, code in blocks.items() if intro.endswith(ending)]
    assert len(found) == 1, f"{GUIDE}: {len(found)} blocks introduced by ...{ending}"
    return found[0]


def guide_commands() -> str:
    """The guide's shell block: the commands it tells a reader to run."""
    return "\n".join(m["code"] for m in FENCED.finditer(GUIDE.read_text()) if m["lang"] == "sh")


@pytest.fixture
def corridor(tmp_path, monkeypatch) -> SmallStudy:
    """The guide's world written and registered, its config and study in a configs dir (sized
    like the small study), the process' settings pointing there; unregistered afterwards."""
    blocks = guide_blocks()
    package = tmp_path / "worlds"
    package.mkdir()
    (package / f"{WORLD}.py").write_text(block_after(blocks, f"`app/worlds/{WORLD}.py`:"))
    monkeypatch.setattr(app.worlds, "__path__", [*app.worlds.__path__, str(package)])
    namespace = dict(vars(registry))  # the builder runs as if written into registry.py
    exec(block_after(blocks, "above `SIMULATED_WORLDS`:"), namespace)
    entry = eval("{" + block_after(blocks, "entry in `SIMULATED_WORLDS`:") + "}", namespace)
    monkeypatch.setitem(registry.SIMULATED_WORLDS, WORLD, entry[WORLD])
    study = SmallStudy(tmp_path / "var", tmp_path / "configs", STUDY)
    write_configs(study.configs_dir, blocks)
    with settings_of(study):
        yield study
    sys.modules.pop(MODULE, None)
    if hasattr(app.worlds, WORLD):
        delattr(app.worlds, WORLD)


def write_configs(configs_dir: Path, blocks: dict[str, str]) -> None:
    """The world's YAML and the study as the guide writes them, the study and training shrunk
    like the small study's."""
    write_small_configs(configs_dir, STUDY)
    world_yaml = block_after(blocks, f"`study_configs/worlds/{WORLD}.yaml`:")
    (configs_dir / "worlds" / f"{WORLD}.yaml").write_text(world_yaml)
    study_path = configs_dir / f"{STUDY}.yaml"
    study = yaml.safe_load(study_path.read_text())
    study |= yaml.safe_load(block_after(blocks, f"`study_configs/{STUDY}.yaml`:"))
    study_path.write_text(yaml.safe_dump(study | SMALL_STUDY_OVERRIDES | ONE_SEED))
    training_path = configs_dir / "training.yaml"
    training = yaml.safe_load(training_path.read_text()) | {"selected": SELECTED}
    training_path.write_text(yaml.safe_dump(training))


def tomstudy(*args: str) -> str:
    """Run one CLI command in this process (where the world is registered); its output."""
    assert f"tomstudy {args[0]}" in guide_commands(), f"the guide never runs `{args[0]}`"
    result = CliRunner().invoke(cli, list(args))
    assert result.exit_code == 0, (result.output, result.exception)
    return result.output


def test_the_guides_world_simulates_trains_banks_and_serves(corridor, tmp_path):
    world = registry.build_world(WORLD)
    assert isinstance(world, registry.SimulatedWorld)
    tomstudy("simulate", WORLD, "--n", "40", "--seed", "0", "--workers", "1")
    trajs = TrajectorySet.load(corridor.layout.trajectories(WORLD))
    assert (trajs.world, len(trajs)) == (WORLD, 40)
    assert sorted(set(trajs.labels[world.robot_label].tolist())) == [0, 1]
    assert trajs.scene.goals and not trajs.scene.lanes  # the pilot bots read goal intents

    tomstudy("bundle", "build", "--study", STUDY, "--workers", "1", "--replications", "0")
    bank = corridor.layout.bundle_dir(STUDY)
    assert (bank / "manifest.json").is_file()
    with make_client(corridor, f"sqlite:///{tmp_path / 'study.db'}") as client:
        participant = at_first_trial(client, STUDY)
        trial = participant.state()["step"]
        assert trial["scene"]["world"] == WORLD
        assert participant.finish()["phase"] == "done"


def test_the_guides_world_leaves_nothing_registered():
    assert WORLD not in registry.SIMULATED_WORLDS and MODULE not in sys.modules
    with pytest.raises(ConfigError, match=f"'{WORLD}'.*highway, obstacle"):
        registry.build_world(WORLD)


def test_corridor_policy_heads_for_the_labelled_exit(corridor):
    world = registry.build_world(WORLD)
    start = np.array([[1.0, 3.0], [6.0, 0.3]])
    upper = world.robot_policy_actions(start, 0.0, 1.0, np.zeros(2), {"robot_exit": 0}, 3,
                                       np.random.default_rng(0))
    lower = world.robot_policy_actions(start, 0.0, 1.0, np.zeros(2), {"robot_exit": 1}, 3,
                                       np.random.default_rng(0))
    assert upper.shape == (3, 2) and (upper[:, 0] > 0).all()
    assert upper[:, 1].mean() < 0 < lower[:, 1].mean()  # y grows downwards
