"""The World protocol: both worlds implement all of it, and the trial bank's world rules."""

import numpy as np
import pytest
from typer.testing import CliRunner

from app.cli import cli
from app.configio import ConfigError
from app.data.trajectory import Covered
from app.worlds.registry import SIMULATED_WORLDS, World, build_world


@pytest.fixture(scope="module")
def worlds() -> dict[str, World]:
    return {name: build_world(name) for name in SIMULATED_WORLDS}


def test_every_world_implements_the_whole_protocol(worlds):
    for world in worlds.values():
        assert isinstance(world, World), world.name


def test_highway_has_no_sac_policy():
    with pytest.raises(ConfigError, match="highway supports only 'mpc'"):
        build_world("highway", policy="sac")


def test_obstacle_names_its_two_policies():
    with pytest.raises(ConfigError, match="unknown policy 'rrt' for obstacle; choose mpc or sac"):
        build_world("obstacle", policy="rrt")


def test_a_registered_world_decides_its_own_policies(monkeypatch):
    """A world with a policy no other world has is built from its builder alone (the guide's
    promise); there is no second, global list of policies to extend."""
    monkeypatch.setitem(SIMULATED_WORLDS, "corridor", lambda path, policy: policy)
    assert build_world("corridor", policy="rule") == "rule"


def test_an_unknown_world_with_a_yaml_is_refused_naming_the_registered_ones(tmp_path):
    path = tmp_path / "third.yaml"
    # a name in the old tuple of simulated worlds without a branch of its own was built as
    # Obstacle; now only a registered builder builds a simulated world
    path.write_text("dt_s: 0.5\n")
    with pytest.raises(ConfigError, match=r"'third' is not a simulated world \(those are "
                                          r"highway, obstacle"):
        build_world("third", path)


def test_help_texts_list_the_registered_worlds():
    for command in (["simulate"], ["train"], ["sweep"], ["select"]):
        output = CliRunner().invoke(cli, [*command, "--help"], terminal_width=200).output
        assert ", ".join(SIMULATED_WORLDS) in output, command
        assert "highway or obstacle" not in output


def test_highway_segments_end_during_the_lane_change(worlds):
    across = np.linspace(0.0, 4.0, 11)  # one lane to the left of lane 0 ... straight across
    track = np.stack([np.arange(11.0), across], axis=1)
    ends = worlds["highway"].visible_ends(track, np.arange(11))
    assert ends.tolist() == [1, 2, 3, 4, 5, 6, 7]  # 10% .. 70% of the way across
    keep = np.stack([np.arange(11.0), np.zeros(11)], axis=1)
    assert worlds["highway"].visible_ends(keep, np.arange(11)).tolist() == list(range(7))


def test_obstacle_segments_end_well_before_the_goal(worlds):
    track = np.stack([np.arange(11.0), np.zeros(11)], axis=1)
    ends = worlds["obstacle"].visible_ends(track, np.arange(11))
    assert ends.tolist() == list(range(7))  # at least 4 of the 10 m still to go


def test_data_start_kinds_are_the_worlds_own(worlds):
    segment = np.array([[[0.0, 4.0], [-20.0, 8.0]], [[3.0, 4.0], [-18.0, 8.0]]])
    covered = Covered(np.array([[4.0, 4.0], [5.0, 0.0], [6.0, 8.0], [40.0, 4.0]]), np.zeros(4))
    highway = worlds["highway"]
    pools = highway.data_start_candidates(highway.scene(), segment, covered, 9.0)
    assert list(pools) == ["same_lane", "adjacent_lane"]
    assert pools["same_lane"].tolist() == [0]
    assert sorted(pools["adjacent_lane"].tolist()) == [1, 2]
    obstacle = worlds["obstacle"]
    assert list(obstacle.data_start_candidates(obstacle.scene(), segment + 5, covered,
                                               1.0)) == ["near", "mid"]
