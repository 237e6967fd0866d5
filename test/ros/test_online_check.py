"""online_check: a bag excerpt replayed through the predictor node matches the offline model."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import REPO, quick_preprocess

from id_learning.errors import CheckpointError
from id_learning.online_check import online_check

pytestmark = pytest.mark.ros

#: The study's MLP at its smallest, one epoch: the check needs a model, not a good one.
TINY_MLP = {'width': 8, 'depth': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 16}
SECONDS = 4.0


@pytest.fixture(scope='module')
def trained(tmp_path_factory, short_twin):
    """A 26 s twin bag and a training run on it (tiny MLP), as ``make demo`` makes them."""
    from id_learning.dataset.recording import write_recording
    from id_learning.training.trainer import train_run

    config, result = short_twin
    folder = tmp_path_factory.mktemp('online_check')
    bag = write_recording(result.recording, folder / 'bag', config.robot.topics)
    # Labels low-passed at 2 Hz: 26 s are too short to fit through the study's 0.3 Hz filter.
    run = train_run(
        [bag], config.robot, 'motor', ['mlp'], folder / 'run', hyper={'mlp': TINY_MLP},
        progress=False, preprocess=quick_preprocess(),
    )  # fmt: skip
    return bag, run.models['mlp'].folder


@pytest.mark.slow  # a training run, then 4 s replayed through the predictor node
def test_online_check_gives_the_offline_prediction_for_every_replayed_sample(
    trained, domain_id, tmp_path
):
    bag, artifact = trained
    out = tmp_path / 'online_check.json'
    start = time.perf_counter()
    result = online_check(
        bag,
        REPO / 'config/mabi_max100.yaml',
        artifact,
        seconds=SECONDS,
        out=out,
        domain_id=domain_id,
        input_depth=2 * round(SECONDS / 0.008),  # a stall of the loaded CI machine drops nothing
        max_age_s=0.0,  # nor refuses a sample as too old: the model is under test, not time
        progress=False,
    )
    wall_ms = (time.perf_counter() - start) * 1e3
    expected = round(SECONDS / 0.008)
    assert not result.is_clipped
    assert result.test_s > SECONDS  # precondition: the excerpt lies inside the test part
    assert result.n_samples == expected
    # Every input got an output, stamped so that it matches its sample.
    assert result.n_inputs == expected
    assert result.n_outputs == expected, (result.notes, result.predictor)
    assert result.n_missing == 0
    assert result.predictor['published'] == str(expected)
    assert result.predictor['rejected'] == '0'
    assert result.predictor['clamped_samples'] == '0'
    # Same inputs, same artifact: the node's torque is the model's (float32 networks).
    scale = np.max(result.rmse_offline_nm)
    assert scale > 0
    np.testing.assert_array_less(result.max_abs_node_error_nm, 1e-5 * scale)
    # The replay sends the recorded positions, and velocities smoothed like the controller's
    # inputs over a shorter span than the whole recording: close, not equal. Through the
    # label filter (|H| <= 1), |RMSE(F x) - RMSE(F y)| <= max |x - y| whatever the inputs.
    np.testing.assert_array_equal(result.max_input_diff['q'], 0.0)
    assert np.max(result.max_input_diff['v']) < 1e-3
    gap = np.abs(result.rmse_online_nm - result.rmse_offline_nm)
    assert np.all(gap <= result.max_abs_online_offline_nm + 1e-9)
    # Latencies in ms, over every published sample: ordered, each sample's model call (compute)
    # inside its receive-to-publish span, and no span longer than the whole check.
    stats = {key: float(result.predictor[key]) for key in result.predictor if key.endswith('_ms')}
    assert int(result.predictor['latency_samples']) == expected
    for kind in ('latency', 'compute'):
        assert stats[f'{kind}_median_ms'] <= stats[f'{kind}_p99_ms'] <= stats[f'{kind}_max_ms']
    for statistic in ('median', 'max'):
        assert stats[f'compute_{statistic}_ms'] <= stats[f'latency_{statistic}_ms']
    assert stats['latency_max_ms'] < wall_ms
    assert json.loads(out.read_text())['n_outputs'] == expected
    assert 'missing' in result.summary()


def test_online_check_refuses_a_folder_that_is_no_artifact_before_starting_nodes(
    trained, tmp_path
):
    bag, _ = trained
    with pytest.raises(CheckpointError, match='no_artifact'):
        online_check(
            bag, REPO / 'config/mabi_max100.yaml', tmp_path / 'no_artifact', progress=False
        )
