"""FeedForwardPredictor without ROS: online equals offline, and every guard does its job."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest
from predictor.tiny_artifacts import reference_run

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.registry import STUDY_MODELS, load_model
from id_learning.predictor import (
    FeedForwardPredictor,
    GuardConfig,
    ReferenceSample,
    Reject,
    TrainingRange,
    causal_acceleration,
    training_range,
)

PERIOD_NS = 8_000_000
JOINTS = tuple(f'joint_{i}' for i in range(1, 7))


class LinearModel(InverseDynamicsModel):
    """tau = 10 q + 2 v + a (per joint), or NaN where q > 100: a fast stand-in model."""

    kind: ClassVar[str] = 'linear'

    def __init__(self, robot) -> None:
        self.robot = robot
        self.calls = 0

    def fit(self, data, *, progress=False):
        return self

    def predict(self, q, v, a):
        self.calls += 1
        tau = 10.0 * np.asarray(q) + 2.0 * np.asarray(v) + np.asarray(a)
        return np.where(np.asarray(q) > 100, np.nan, tau)

    def state(self):
        return {}

    def load_state(self, tensors, fitted):
        pass


def sample(k: int, *, q=None, v=None, a=None, names=JOINTS, stamp_ns=None, with_a=True):
    n = len(names)
    return ReferenceSample(
        stamp_ns=stamp_ns if stamp_ns is not None else 1_000_000_000 + k * PERIOD_NS,
        names=tuple(names),
        q=np.full(n, 0.01 * k) if q is None else np.asarray(q, float),
        v=np.full(n, 0.1) if v is None else np.asarray(v, float),
        a=(np.zeros(n) if a is None else np.asarray(a, float)) if with_a else None,
    )


def receive(k: int) -> int:
    """A monotonic receive time in step with the stamps."""
    return 5_000_000_000 + k * PERIOD_NS


@pytest.fixture
def linear(mabi) -> FeedForwardPredictor:
    return FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())


# -- online == offline ----------------------------------------------------------------------------
@pytest.mark.parametrize('kind', STUDY_MODELS)
def test_online_torque_equals_the_offline_prediction_for_every_model_kind(
    kind, tiny_artifacts, mabi
):
    stamps, q, v, a = reference_run(40)
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts[kind], mabi)
    online = []
    for k in range(len(stamps)):
        result = predictor.step(
            ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k], a[k]), receive(k)
        )
        assert result.reject is None, result.detail
        online.append(result.tau)
    model = load_model(tiny_artifacts[kind], mabi)
    offline = np.clip(model.predict(q, v, a), -mabi.limits.torque, mabi.limits.torque)
    scale = np.abs(offline).max()
    assert scale > 0
    np.testing.assert_allclose(np.array(online), offline, rtol=1e-5, atol=1e-6 * scale)


@pytest.mark.parametrize('kind', STUDY_MODELS)
def test_numpy_and_torch_inference_give_the_same_torque_across_a_history_reset(
    kind, tiny_artifacts, mabi
):
    stamps, q, v, a = reference_run(50)
    stamps = stamps.copy()
    stamps[30:] += 100 * PERIOD_NS  # a hole in the trajectory: the history restarts there
    outputs = {}
    for inference in ('numpy', 'torch'):
        predictor = FeedForwardPredictor.from_artifact(
            tiny_artifacts[kind], mabi, inference=inference
        )
        results = [
            predictor.step(
                ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k], a[k]),
                receive(k) + int(stamps[k] - stamps[0]) - k * PERIOD_NS,  # silent in the hole
            )
            for k in range(len(stamps))
        ]
        assert predictor.counters.history_resets == 1
        outputs[inference] = np.array([result.tau for result in results])
    scale = np.abs(outputs['torch']).max()
    assert scale > 0
    np.testing.assert_allclose(outputs['numpy'], outputs['torch'], rtol=1e-5, atol=1e-6 * scale)


@pytest.mark.parametrize('kind', ['lstm', 'delan'])
def test_warm_up_leaves_no_trace_in_the_output_or_the_counters(kind, tiny_artifacts, mabi):
    stamps, q, v, a = reference_run(25)
    outputs = []
    for warm in (False, True):
        predictor = FeedForwardPredictor.from_artifact(tiny_artifacts[kind], mabi)
        if warm:
            predictor.warm_up()
            assert predictor.counters.received == 0
            assert predictor.compute_s.total == 0
        outputs.append(
            [
                predictor.step(
                    ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k], a[k]), receive(k)
                ).tau
                for k in range(len(stamps))
            ]
        )
    np.testing.assert_array_equal(np.array(outputs[1]), np.array(outputs[0]))


def test_predictor_refuses_an_unknown_inference_backend(mabi):
    with pytest.raises(ValueError, match="inference must be one of \\('numpy', 'torch'\\)"):
        FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, inference='onnx')


@pytest.mark.parametrize('kind', ['mlp', 'lstm'])
def test_estimated_accelerations_match_the_batch_estimate_offline(kind, tiny_artifacts, mabi):
    stamps, q, v, _ = reference_run(30)
    config = GuardConfig(acceleration_cutoff_hz=20.0)
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts[kind], mabi, config)
    online = [
        predictor.step(ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k]), receive(k)).tau
        for k in range(len(stamps))
    ]
    a = causal_acceleration(stamps, v, cutoff_hz=20.0)
    assert np.abs(a[1:]).max() > 0  # the estimate is not trivially zero
    offline = load_model(tiny_artifacts[kind], mabi).predict(q, v, a)
    # float64 one-sample path against the float32 network: equal to float32 rounding
    np.testing.assert_allclose(np.array(online), offline, rtol=1e-5, atol=1e-4)


def test_predictor_reorders_joints_by_name(linear):
    order = [3, 0, 5, 1, 4, 2]
    q = np.arange(6) * 0.1
    shuffled = sample(0, q=q[order], v=np.ones(6)[order], names=[JOINTS[i] for i in order])
    result = linear.step(shuffled, receive(0))
    np.testing.assert_allclose(result.tau, 10 * q + 2)


def test_predictor_refuses_an_artifact_of_another_robot(tiny_artifacts, mabi):
    from dataclasses import replace

    other = replace(mabi, name='another_robot')
    with pytest.raises(CheckpointError, match='another_robot'):
        FeedForwardPredictor.from_artifact(tiny_artifacts['mlp'], other)


# -- guards ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('bad', 'reason'),
    [
        (
            sample(1, names=JOINTS[:5], q=np.zeros(5), v=np.zeros(5), a=np.zeros(5)),
            Reject.JOINT_COUNT,
        ),
        (sample(1, names=(*JOINTS[:5], 'joint_x')), Reject.JOINT_NAMES),
        (sample(1, names=(*JOINTS[:5], 'joint_5')), Reject.JOINT_NAMES),
        (sample(1, q=np.zeros(5)), Reject.SHAPE),
        (sample(1, v=np.array([])), Reject.SHAPE),
        (sample(1, q=[0, 0, np.nan, 0, 0, 0]), Reject.NON_FINITE),
        (sample(1, v=[0, 0, 0, np.inf, 0, 0]), Reject.NON_FINITE),
        (sample(1, a=[-np.inf, 0, 0, 0, 0, 0]), Reject.NON_FINITE),
        (sample(1, stamp_ns=1_000_000_000), Reject.STAMP_ORDER),
        (sample(1, stamp_ns=999_000_000), Reject.STAMP_ORDER),
    ],
)
def test_predictor_rejects_bad_samples_and_keeps_running(linear, bad, reason):
    assert linear.step(sample(0), receive(0)).tau is not None
    calls = linear.model.calls
    result = linear.step(bad, receive(1))
    assert result.tau is None
    assert result.reject is reason
    assert result.detail
    assert linear.model.calls == calls  # the model never saw it
    assert linear.counters.rejects[reason] == 1
    assert linear.counters.rejected == 1
    follow_up = linear.step(sample(2), receive(2))
    assert follow_up.tau is not None
    assert np.isfinite(follow_up.tau).all()


@pytest.mark.parametrize(
    ('change', 'detail'),
    [
        ({'v': 6.0}, 'velocity of joint_1 10.2 rad/s exceeds 1.5 x its limit'),
        ({'q': 1e300}, 'position of joint_1 1e+300 rad is outside its limits'),
        ({'a': 1e6}, 'acceleration of joint_1 1e+06 rad/s^2 exceeds 2 x its limit'),
    ],
)
def test_a_sample_no_arm_can_be_in_gives_no_torque_and_the_next_valid_one_does(
    tiny_artifacts, mabi, change, detail
):
    stamps, q, v, a = reference_run(6)
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts['mlp'], mabi)

    def at(k: int, **values) -> ReferenceSample:
        state = [values.get(name, array[k]) for name, array in (('q', q), ('v', v), ('a', a))]
        return ReferenceSample(int(stamps[k]), JOINTS, *state)

    for k in range(3):
        assert predictor.step(at(k), receive(k)).tau is not None
    bad = {name: getattr(at(3), name).copy() for name in ('q', 'v', 'a')}
    ((name, value),) = change.items()
    bad[name][0] = value * mabi.limits.velocity[0] if name == 'v' else value
    result = predictor.step(at(3, **bad), receive(3))
    assert result.tau is None
    assert result.reject is Reject.IMPOSSIBLE
    assert detail in result.detail
    assert predictor.counters.rejects[Reject.IMPOSSIBLE] == 1
    # Valid input again: the torque the model gives for it, as if nothing had happened.
    after = predictor.step(at(4), receive(4))
    expected = predictor.model.predict(q[4:5], v[4:5], a[4:5])[0]
    np.testing.assert_allclose(after.tau, expected, rtol=1e-5, atol=1e-6)


def test_cycles_the_stamps_jump_over_are_counted_as_skipped(linear):
    for k in (0, 1, 2, 5, 6):  # samples 3 and 4 never arrive
        assert linear.step(sample(k), receive(k)).tau is not None
    assert linear.counters.skipped_cycles == 2
    bad = sample(7, q=[np.nan] * 6)  # rejected: its cycle gives no torque either
    assert linear.step(bad, receive(7)).tau is None
    assert linear.step(sample(8), receive(8)).tau is not None
    assert linear.counters.skipped_cycles == 3
    # A jump beyond the stale threshold is a new run (a history reset), not skipped cycles.
    assert linear.step(sample(100), receive(100)).tau is not None
    assert linear.counters.skipped_cycles == 3
    assert linear.counters.history_resets == 1


def test_a_sample_later_than_max_age_against_its_time_base_is_too_old(mabi):
    predictor = FeedForwardPredictor(
        LinearModel(mabi), mabi.limits.torque, GuardConfig(max_age_s=0.1)
    )
    # The stamps are an hour off this clock: the time base learns the offset, no shared clock.
    hour = 3600 * 10**9
    assert predictor.step(sample(0), receive(0) + hour).tau is not None
    result = predictor.step(sample(1), receive(1) + hour + 150_000_000)
    assert result.reject is Reject.TOO_OLD
    assert '150.0 ms later' in result.detail
    assert predictor.step(sample(2), receive(2) + hour + 50_000_000).tau is not None
    # On the caller's clock (a ROS clock) rather than the receive time.
    clocked = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    for k, late in ((0, 0), (1, 0), (2, 200_000_000)):
        stamp = sample(k).stamp_ns
        result = clocked.step(sample(k), receive(0), clock_ns=stamp + 2_000_000 + late)
    assert result.reject is Reject.TOO_OLD


def test_a_stamp_far_ahead_is_refused_and_never_locks_the_stream_out(mabi):
    predictor = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig())
    assert predictor.step(sample(0), receive(0)).tau is not None
    hour = 3600 * 10**9
    ahead = predictor.step(sample(1, stamp_ns=sample(1).stamp_ns + hour), receive(1))
    assert ahead.reject is Reject.FUTURE_STAMP
    assert all(predictor.step(sample(k), receive(k)).tau is not None for k in range(2, 20))
    assert predictor.counters.resyncs == 0


def test_a_clock_step_on_the_sender_resynchronises_after_resync_after_rejections(mabi):
    config = GuardConfig(resync_after=5)
    predictor = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, config)
    for k in range(10):
        assert predictor.step(sample(k), receive(k)).tau is not None
    back = -3600 * 10**9  # the sender's clock steps an hour back, for good
    results = [
        predictor.step(sample(k, stamp_ns=sample(k).stamp_ns + back), receive(k))
        for k in range(10, 30)
    ]
    assert [r.reject for r in results[:4]] == [Reject.TOO_OLD] * 4  # an hour later than due
    assert results[4].resynced
    assert results[4].tau is not None
    assert all(r.tau is not None for r in results[4:])
    assert predictor.counters.resyncs == 1


def test_predictor_clamps_to_the_torque_limits_and_counts_per_joint(mabi):
    config = GuardConfig(torque_limit_scale=0.5)
    predictor = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, config)
    limit = 0.5 * mabi.limits.torque
    a = np.zeros(6)
    a[0] = 2 * limit[0]
    a[4] = -10 * limit[4]
    a[2] = 0.9 * limit[2]  # inside: kept as it is
    result = predictor.step(sample(0, q=np.zeros(6), v=np.zeros(6), a=a), receive(0))
    assert result.is_clamped
    np.testing.assert_array_equal(result.tau, [limit[0], 0, 0.9 * limit[2], 0, -limit[4], 0])
    assert predictor.counters.clamped_samples == 1
    assert predictor.counters.clamped_per_joint.tolist() == [1, 0, 0, 0, 1, 0]
    assert not predictor.step(sample(1, q=np.zeros(6), v=np.zeros(6)), receive(1)).is_clamped
    assert predictor.counters.clamped_samples == 1


def test_predictor_never_returns_a_non_finite_torque(linear):
    result = linear.step(sample(0, q=[0, 0, 0, 0, 0, 101.0]), receive(0))
    assert result.tau is None
    assert result.reject is Reject.NON_FINITE_OUTPUT
    assert linear.counters.predicted == 0


def test_predictor_goes_stale_once_per_episode_and_resumes(mabi):
    # max_age_s off: the samples below are far later than their time base would allow.
    linear = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig(max_age_s=0))
    threshold = linear.config.stale_after_ns
    assert not linear.check_stale(receive(0))  # nothing received yet: waiting, not stale
    linear.step(sample(0), receive(0))
    assert not linear.check_stale(receive(0) + threshold)
    assert linear.check_stale(receive(0) + threshold + 1)
    assert linear.is_stale
    assert not linear.check_stale(receive(0) + 10 * threshold)  # same episode
    assert linear.counters.stale_episodes == 1
    resets = linear.counters.history_resets
    # Late but with the next stamp: the trajectory is contiguous, the history is kept.
    result = linear.step(sample(1), receive(0) + 11 * threshold)
    assert result.resumed_after_stale
    assert not linear.is_stale
    assert linear.counters.history_resets == resets
    assert linear.counters.stale_episodes == 1
    # A jump in the stamps is a hole in the trajectory: a new episode, and a reset.
    result = linear.step(sample(100), receive(0) + 12 * threshold)
    assert result.resumed_after_stale
    assert linear.counters.history_resets == resets + 1
    assert linear.counters.stale_episodes == 2


def test_late_samples_with_contiguous_stamps_keep_the_lstm_window(tiny_artifacts, mabi):
    stamps, q, v, a = reference_run(40)
    # max_age_s off: a stall of 400 ms would otherwise be too old.
    predictor = FeedForwardPredictor.from_artifact(
        tiny_artifacts['lstm'], mabi, GuardConfig(max_age_s=0)
    )
    outputs = []
    for k in range(40):
        late = 10 * predictor.config.stale_after_ns if k >= 20 else 0  # a stall in delivery
        sample_k = ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k], a[k])
        outputs.append(predictor.step(sample_k, receive(k) + late).tau)
    assert predictor.counters.stale_episodes == 1
    assert predictor.counters.history_resets == 0
    offline = load_model(tiny_artifacts['lstm'], mabi).predict(q, v, a)
    np.testing.assert_allclose(np.array(outputs), offline, rtol=1e-5, atol=1e-6)


def test_a_gap_in_the_stamps_resets_the_lstm_window_as_a_new_run(tiny_artifacts, mabi):
    stamps, q, v, a = reference_run(50)
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts['lstm'], mabi)
    gap_ns = 10 * PERIOD_NS  # the sender paused: its stamps and their arrival leap together
    outputs = []
    for k in range(50):
        gap = gap_ns if k >= 25 else 0
        sample_k = ReferenceSample(int(stamps[k]) + gap, JOINTS, q[k], v[k], a[k])
        result = predictor.step(sample_k, receive(k) + gap)
        outputs.append(result.tau)
    assert predictor.counters.history_resets == 1
    assert predictor.counters.stale_episodes == 1
    model = load_model(tiny_artifacts['lstm'], mabi)
    second_run = model.predict(q[25:], v[25:], a[25:])
    np.testing.assert_allclose(np.array(outputs[25:]), second_run, rtol=1e-5, atol=1e-6)
    continuous = model.predict(q, v, a)[25:]
    assert not np.allclose(second_run[:5], continuous[:5], rtol=1e-6, atol=1e-9)


def test_a_rejected_sample_leaves_the_lstm_window_untouched(tiny_artifacts, mabi):
    stamps, q, v, a = reference_run(30)
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts['lstm'], mabi)
    outputs = []
    for k in range(30):
        if k == 10:
            bad = q[k].copy()
            bad[2] = np.nan
            rejected = predictor.step(
                ReferenceSample(int(stamps[k]), JOINTS, bad, v[k], a[k]), receive(k)
            )
            assert rejected.reject is Reject.NON_FINITE
            continue
        outputs.append(
            predictor.step(
                ReferenceSample(int(stamps[k]), JOINTS, q[k], v[k], a[k]), receive(k)
            ).tau
        )
    keep = np.arange(30) != 10
    offline = load_model(tiny_artifacts['lstm'], mabi).predict(q[keep], v[keep], a[keep])
    np.testing.assert_allclose(np.array(outputs), offline, rtol=1e-5, atol=1e-6)


# -- training range -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('kind', 'quantities', 'source'),
    [
        ('mlp', {'q', 'v', 'a'}, 'input_scaler'),
        ('lstm', {'q', 'v', 'a'}, 'input_scaler'),
        ('rnea_mlp', {'q', 'v'}, 'state_scaler'),
        ('delan', {'q', 'v'}, 'scaling'),
        ('lnn', {'q', 'v'}, 'scaling'),
        ('lnn_mlp', {'q', 'v'}, 'scaling'),
        ('rnea_lq', {'q', 'v', 'a'}, 'robot joint limits'),
    ],
)
def test_training_range_comes_from_each_kinds_fitted_metadata(
    kind, quantities, source, tiny_artifacts, mabi
):
    from predictor.tiny_artifacts import training_recording

    bounds = training_range(load_model(tiny_artifacts[kind], mabi).fitted_metadata(), mabi)
    assert set(bounds.bounds) == quantities
    assert source in bounds.source
    if source != 'robot joint limits':
        # Fitted on the (low-passed) training part of the sine recording, which lies inside
        # up to the filter's smoothing of the peaks.
        q = training_recording().position
        low, high = bounds.bounds['q']
        assert np.all(low <= q[:100].min(axis=0) + 0.02)
        assert np.all(high >= q[:100].max(axis=0) - 0.02)
        assert np.all(high - low < 1.01)  # the sines' amplitude is 0.5 rad


def test_inputs_outside_the_training_range_are_warned_about_or_rejected(mabi):
    bounds = TrainingRange(JOINTS, {'q': (np.full(6, -1.0), np.full(6, 1.0))}, 'test range')
    warn = FeedForwardPredictor(LinearModel(mabi), mabi.limits.torque, GuardConfig(), bounds)
    q = np.zeros(6)
    q[3] = 1.04  # inside the 5 % margin
    assert not warn.step(sample(0, q=q), receive(0)).is_out_of_range
    q[3] = 1.2
    result = warn.step(sample(1, q=q), receive(1))
    assert result.is_out_of_range
    assert result.tau is not None
    assert 'q of joint_4 = 1.2 rad' in result.detail
    assert 'test range' in result.detail
    assert warn.counters.out_of_range == 1

    reject = FeedForwardPredictor(
        LinearModel(mabi), mabi.limits.torque, GuardConfig(out_of_range='reject'), bounds
    )
    result = reject.step(sample(0, q=q), receive(0))
    assert result.reject is Reject.OUT_OF_RANGE
    assert result.tau is None


def test_update_config_applies_new_limits_to_the_running_stream(linear, mabi):
    from dataclasses import replace

    q = np.zeros(6)
    q[0] = 50.0
    assert not linear.step(sample(0, q=q, v=np.zeros(6)), receive(0)).is_clamped
    linear.update_config(replace(linear.config, torque_limit_scale=0.01))
    result = linear.step(sample(1, q=q, v=np.zeros(6)), receive(1))
    assert result.is_clamped
    assert result.tau[0] == pytest.approx(0.01 * mabi.limits.torque[0])


@pytest.mark.parametrize(
    ('overrides', 'key'),
    [
        ({'period_s': 0.0}, 'period_s'),
        ({'stale_after_cycles': 0}, 'stale_after_cycles'),
        ({'max_age_s': -1.0}, 'max_age_s'),
        ({'acceleration_cutoff_hz': -1.0}, 'acceleration_cutoff_hz'),
        ({'torque_limit_scale': 1.5}, 'torque_limit_scale'),
        ({'range_margin': -0.1}, 'range_margin'),
        ({'out_of_range': 'ignore'}, 'out_of_range'),
    ],
)
def test_guard_config_rejects_bad_values_naming_the_key(overrides, key):
    with pytest.raises(ConfigError, match=key):
        GuardConfig(**overrides)


@pytest.mark.parametrize(
    ('change', 'said'),
    [
        ({'q': np.zeros((6, 1))}, 'q has shape (6, 1), expected (6,)'),
        ({'v': np.zeros(6, dtype=complex)}, 'v holds complex128 values, expected real numbers'),
        ({'a': np.array(['0'] * 6)}, 'a holds <U1 values'),
        (  # a JointTrajectory without points (msg_conversions says so)
            {
                'q': np.empty(0),
                'v': np.empty(0),
                'a': None,
                'lacks': 'the JointTrajectory has no points',
            },
            'the JointTrajectory has no points: no joint values to predict from',
        ),
    ],
)
def test_a_sample_of_the_wrong_shape_or_type_is_refused_saying_which(linear, change, said):
    fields = {'q': np.zeros(6), 'v': np.zeros(6), 'a': np.zeros(6), **change}
    result = linear.step(ReferenceSample(PERIOD_NS, JOINTS, **fields), receive(0))
    assert result.reject is Reject.SHAPE
    assert said in result.detail
