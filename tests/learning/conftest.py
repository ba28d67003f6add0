"""Shared fixtures: analytic trajectories and one small trained model of each (Ours, VAE)."""

import pytest

from app.learning.config import TrainConfig
from app.learning.train import ours_code_count, train_and_save
from tests.learning.synthetic import make_lane_trajs

FAST = TrainConfig(max_epochs=6, windows_per_trajectory=6, encoder_hidden=[32, 32],
                   decoder_hidden=[32, 32], levels=[3, 3])


@pytest.fixture(scope="session")
def lane_trajs():
    """300 analytic lane-keeping / merging trajectories."""
    return make_lane_trajs(300)


@pytest.fixture(scope="session")
def trained(lane_trajs, tmp_path_factory):
    """Checkpoint paths of a few-epoch Ours and VAE trained on `lane_trajs`."""
    root = tmp_path_factory.mktemp("models")
    ours = train_and_save(lane_trajs, "ours", 0, FAST, root / "ours", progress=False)
    vae = train_and_save(lane_trajs, "vae", 0, FAST, root / "vae", progress=False,
                         vae_clusters=ours_code_count(ours, lane_trajs.world))
    return {"ours": ours, "vae": vae}
