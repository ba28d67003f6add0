"""Training outputs, the checkpoint format and the numpy inference interface."""

import json

import numpy as np
import pytest
import torch

from app.data.windows import make_windows, segment_features
from app.learning.checkpoint import CheckpointError, check_matches_data, load_model
from app.learning.fsq import FSQ
from app.learning.train import train_and_save
from tests.learning.conftest import FAST


@pytest.mark.parametrize("model_name", ["ours", "vae"])
def test_training_writes_checkpoint_metrics_and_loss_curve(trained, model_name):
    path = trained[model_name]
    assert (path.parent / "loss.png").stat().st_size > 1000
    metrics = json.loads((path.parent / "metrics.json").read_text())
    assert metrics["kind"] == model_name and 1 <= metrics["epochs_run"] <= FAST.max_epochs
    test = metrics["test"]
    assert {"usage", "agreement", "prediction", "constant_velocity"} <= set(test)
    assert 0 < test["agreement"]["robot_intent"]["purity"] <= 1
    assert "robot_intent_in_progress" in test["agreement"]
    raw = torch.load(path, weights_only=True)  # plain dict of tensors and plain types
    assert raw["kind"] == model_name and raw["train_config"]["segment_len"] == FAST.segment_len
    assert raw["content_hash"] == load_model(path).content_hash


def test_checkpoint_attributes(trained):
    ours, vae = load_model(trained["ours"]), load_model(trained["vae"])
    assert (ours.name, ours.levels, ours.latent_dim) == ("ours", [3, 3], 2)
    assert (vae.name, vae.levels, vae.latent_dim) == ("vae", None, 2)
    for model in (ours, vae):
        assert model.world == "lanes" and model.segment_len == 5 and model.n_actions == 3
        assert model.dt_s == 0.5 and len(model.content_hash) == 64
    # k-means k defaults to the number of codes Ours uses for the same world
    assert len(vae.kmeans_centres) == ours.codes["n_codes_used"]


@pytest.mark.parametrize("model_name", ["ours", "vae"])
def test_numpy_inference_equals_the_torch_network(trained, lane_trajs, model_name):
    model = load_model(trained[model_name])
    net = model.torch_module()
    w = make_windows(lane_trajs, 5, 3, per_trajectory=2)
    z = model.encode_batch(w.segment_positions)
    x = torch.from_numpy(model.norm.features(segment_features(w.segment_positions, 0.5)))
    with torch.no_grad():
        z_torch = net.infer_latent(x).numpy()
        out = net.decode(torch.from_numpy(z_torch),
                         torch.from_numpy(model.norm.states(w.end_states))).numpy()
    assert np.allclose(z, z_torch, atol=1e-5)
    expected = model.norm.unnormalise_actions(out, 3)
    assert np.allclose(model.predict_batch(z, w.end_states), expected, atol=1e-4)


@pytest.mark.parametrize("model_name", ["ours", "vae"])
def test_encode_uses_the_latest_segment_len_steps(trained, lane_trajs, model_name):
    model = load_model(trained[model_name])
    long_segment = lane_trajs.positions[0, :9]  # 8 steps
    assert np.allclose(model.encode(long_segment), model.encode(long_segment[-6:]))
    z = model.encode(long_segment)
    assert z.shape == (model.latent_dim,)
    code = model.code_of(z)
    assert isinstance(code, int) and np.allclose(model.latent_of_code(code).shape, z.shape)
    actions = model.predict(z, lane_trajs.positions[:5, 8])
    assert actions.shape == (5, 3, 2) and actions.dtype == np.float32
    z2, code2, actions2 = model.trial(long_segment, lane_trajs.positions[:5, 8])
    assert code2 == code and np.allclose(actions2, actions)
    with pytest.raises(ValueError, match="segment"):
        model.encode(long_segment[:3])


def test_ours_codes_are_fsq_indices(trained, lane_trajs):
    model = load_model(trained["ours"])
    z = model.encode(lane_trajs.positions[3, :6])
    assert set(np.round(z, 5)) <= {-1.0, 0.0, 1.0}
    assert 0 <= model.code_of(z) < 9
    fsq_index = FSQ([3, 3]).codes_to_indices(torch.from_numpy(z)).item()
    assert model.code_of(z) == fsq_index
    assert np.allclose(model.latent_of_code(fsq_index), z)


def test_same_seed_gives_the_same_checkpoint(lane_trajs, tmp_path, trained):
    again = train_and_save(lane_trajs, "ours", 0, FAST, tmp_path / "again", progress=False)
    assert load_model(again).content_hash == load_model(trained["ours"]).content_hash


def test_how_long_the_data_took_to_simulate_is_not_in_the_content_hash(lane_trajs, tmp_path):
    hashes = set()
    for run, (wall_time_s, workers) in enumerate([(12.3, 1), (45.6, 2)]):
        meta = {"world": "lanes", "seed": 1, "wall_time_s": wall_time_s, "workers": workers}
        path = train_and_save(lane_trajs, "ours", 0, FAST, tmp_path / str(run), data_meta=meta,
                              progress=False)
        model = load_model(path)
        assert model.data_meta["source"] == {"world": "lanes", "seed": 1}
        hashes.add(model.content_hash)
    assert len(hashes) == 1


def test_corrupt_checkpoint_is_a_clear_error(trained, tmp_path):
    good = trained["ours"].read_bytes()
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good[: len(good) // 2])
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        load_model(truncated)
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"definitely not a checkpoint")
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        load_model(junk)
    with pytest.raises(CheckpointError, match="not found"):
        load_model(tmp_path / "missing.pt")


def test_altered_weights_fail_the_content_hash(trained, tmp_path):
    payload = torch.load(trained["ours"], weights_only=True)
    payload["state_dict"]["decoder.0.bias"] += 0.01
    altered = tmp_path / "altered.pt"
    torch.save(payload, altered)
    with pytest.raises(CheckpointError, match="content hash mismatch"):
        load_model(altered)


def test_checkpoint_that_does_not_match_the_data(trained):
    with pytest.raises(CheckpointError, match="for world 'lanes', not 'highway'"):
        load_model(trained["ours"], world="highway")
    model = load_model(trained["ours"])
    with pytest.raises(CheckpointError, match="dt"):
        check_matches_data(model, "lanes", 0.1)
    with pytest.raises(CheckpointError, match="different trajectory file"):
        check_matches_data(model, "lanes", 0.5, data_hash="0" * 64)
    check_matches_data(model, "lanes", 0.5, data_hash=model.data_hash)
