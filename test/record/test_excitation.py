"""design_excitation: rest at home between segments, limits, derivatives, round trip, seeding."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from id_learning.errors import ConfigError
from id_learning.record import (
    ExcitationConfig,
    ExcitationTrajectory,
    FourierSegment,
    check_limits,
    design_excitation,
)
from id_learning.robot import JointLimits, RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
PERIOD_S = 0.008
CONFIG = ExcitationConfig(duration_s=120)
# (robot, seed): three seeds on our arm, one on each of the other robots.
CASES = [('mabi_max100', 0), ('mabi_max100', 1), ('mabi_max100', 2), ('ur5', 3), ('panda', 4)]
CASE_IDS = [f'{name}-seed{seed}' for name, seed in CASES]


@cache
def robot(name: str) -> RobotConfig:
    return load_robot_config(REPO / 'config' / f'{name}.yaml')


@cache
def designed(name: str, seed: int) -> ExcitationTrajectory:
    """The 120 s excitation of a robot for a seed (cached: the trajectory is immutable)."""
    return design_excitation(CONFIG, robot(name).limits, PERIOD_S, np.random.default_rng(seed))


@pytest.fixture(params=CASES, ids=CASE_IDS)
def case(request: pytest.FixtureRequest) -> tuple[JointLimits, ExcitationTrajectory]:
    name, seed = request.param
    return robot(name).limits, designed(name, seed)


def segment_start_times(trajectory: ExcitationTrajectory) -> np.ndarray:
    slot = trajectory.period_s + trajectory.rest_s
    return np.arange(len(trajectory.segments)) * slot + trajectory.rest_s


def test_design_fills_the_duration_with_whole_segments(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    limits, trajectory = case
    # 120 s of (25 s period + 0.5 s rest) slots, keeping 0.5 s for the final rest: 4 segments.
    assert len(trajectory.segments) == 4
    assert trajectory.period_s == 25.0
    assert trajectory.rest_s == 0.5
    assert trajectory.duration_s == pytest.approx(4 * 25.5 + 0.5)
    assert trajectory.duration_s <= CONFIG.duration_s
    np.testing.assert_array_equal(
        trajectory.home, 0.5 * (limits.position_lower + limits.position_upper)
    )
    for segment in trajectory.segments:
        assert segment.a.shape == segment.b.shape == (len(trajectory.home), CONFIG.harmonics)
        assert segment.omega == pytest.approx(2 * math.pi * CONFIG.base_frequency_hz)


def test_every_segment_starts_and_ends_at_home_at_rest(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    _, trajectory = case
    home = trajectory.home

    for segment in trajectory.segments:
        q, qd, qdd = segment.evaluate(np.array([0.0, trajectory.period_s]))
        np.testing.assert_allclose(q, [home, home], rtol=0, atol=1e-9)
        np.testing.assert_allclose(qd, 0.0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(qdd, 0.0, rtol=0, atol=1e-9)
        # ... and moves in between (the boundary check is not one of a motionless segment).
        q_mid, qd_mid, _ = segment.evaluate(np.linspace(0.0, trajectory.period_s, 101))
        assert np.abs(q_mid - home).max(axis=0).min() > 0.05
        assert np.abs(qd_mid).max(axis=0).min() > 0.01


def test_trajectory_rests_at_home_outside_the_segments(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    _, trajectory = case
    starts = segment_start_times(trajectory)
    rests = np.concatenate(
        [
            np.linspace(0.0, starts[0] - 1e-6, 7),
            *[np.linspace(s + trajectory.period_s + 1e-6, s + 25.5 - 1e-6, 7) for s in starts],
        ]
    )
    # Either side of each boundary the trajectory is continuous with the rest.
    boundaries = np.concatenate([starts, starts + trajectory.period_s])

    q, qd, qdd = trajectory.evaluate(rests)
    np.testing.assert_array_equal(q, np.tile(trajectory.home, (len(rests), 1)))
    np.testing.assert_array_equal(qd, 0.0)
    np.testing.assert_array_equal(qdd, 0.0)
    for offset in (-1e-9, 1e-9):
        q, qd, qdd = trajectory.evaluate(boundaries + offset)
        np.testing.assert_allclose(q, np.tile(trajectory.home, (len(boundaries), 1)), atol=1e-8)
        np.testing.assert_allclose(qd, 0.0, atol=1e-8)
        np.testing.assert_allclose(qdd, 0.0, atol=1e-8)


def test_trajectory_stays_inside_its_share_of_every_limit_on_a_dense_grid(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    limits, trajectory = case
    # A grid 10x denser than the IPO cycle, offset from design_excitation's own check grid.
    t = np.arange(0.0, trajectory.duration_s, PERIOD_S / 10) + 0.37e-4
    home = trajectory.home

    q, qd, qdd = trajectory.evaluate(t)

    tolerance = 1e-6  # the design is scaled on a grid; between samples it may overshoot slightly
    reach_high = CONFIG.position_fraction * (limits.position_upper - home)
    reach_low = CONFIG.position_fraction * (home - limits.position_lower)
    assert np.all(q - home <= reach_high + tolerance)
    assert np.all(home - q <= reach_low + tolerance)
    assert np.all(q >= limits.position_lower)
    assert np.all(q <= limits.position_upper)
    assert np.all(np.abs(qd) <= CONFIG.velocity_fraction * limits.velocity + tolerance)
    assert np.all(np.abs(qdd) <= CONFIG.acceleration_fraction * limits.acceleration + tolerance)


def test_each_axis_of_each_segment_reaches_one_of_its_limits(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    # The scaling uses the allowed range: per axis the binding limit is reached, not undershot.
    limits, trajectory = case
    home = trajectory.home
    grid = np.linspace(0.0, trajectory.period_s, int(trajectory.period_s / PERIOD_S * 8) + 1)
    reach_high = CONFIG.position_fraction * (limits.position_upper - home)
    reach_low = CONFIG.position_fraction * (home - limits.position_lower)

    for segment in trajectory.segments:
        q, qd, qdd = segment.evaluate(grid)
        usage = np.maximum.reduce(
            [
                (q - home).max(axis=0) / reach_high,
                (home - q).max(axis=0) / reach_low,
                np.abs(qd).max(axis=0) / (CONFIG.velocity_fraction * limits.velocity),
                np.abs(qdd).max(axis=0) / (CONFIG.acceleration_fraction * limits.acceleration),
            ]
        )
        np.testing.assert_allclose(usage, 1.0, rtol=2e-4)  # DESIGN_MARGIN


def test_velocity_and_acceleration_are_the_derivatives_of_position(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    _, trajectory = case
    t = np.random.default_rng(5).uniform(0.0, trajectory.duration_s, 2000)
    h = 1e-4  # s; central differences err by h^2/6 * (next derivative), about 1e-9 here

    q_plus, qd_plus, _ = trajectory.evaluate(t + h)
    q_minus, qd_minus, _ = trajectory.evaluate(t - h)
    _, qd, qdd = trajectory.evaluate(t)

    assert np.abs(qd).max() > 0.1
    assert np.abs(qdd).max() > 0.05
    np.testing.assert_allclose((q_plus - q_minus) / (2 * h), qd, rtol=0, atol=1e-7)
    np.testing.assert_allclose((qd_plus - qd_minus) / (2 * h), qdd, rtol=0, atol=1e-7)


def test_design_passes_its_own_limit_check(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    limits, trajectory = case
    check_limits(trajectory, limits, PERIOD_S / 8)


def scaled(trajectory: ExcitationTrajectory, index: int, factor: float) -> ExcitationTrajectory:
    """The trajectory with segment ``index``'s a, b scaled, still starting at home."""
    segments = list(trajectory.segments)
    old = segments[index]
    orders = np.arange(1, old.a.shape[1] + 1)
    b = factor * old.b
    q0 = trajectory.home + (b / (old.omega * orders)).sum(axis=1)
    segments[index] = FourierSegment(factor * old.a, b, q0, old.omega)
    return replace(trajectory, segments=tuple(segments))


@pytest.mark.parametrize('quantity', ['position', 'velocity', 'acceleration'])
def test_check_limits_names_the_quantity_a_tripled_segment_exceeds(quantity: str) -> None:
    trajectory = designed('mabi_max100', 0)
    limits = robot('mabi_max100').limits
    t = np.arange(0.0, trajectory.duration_s, PERIOD_S)
    q, qd, qdd = trajectory.evaluate(t)
    # Only the quantity under test is limited (1.5x what the design reaches); the rest is free.
    wide = 1e6 * np.ones_like(limits.velocity)
    home = trajectory.home
    span = 1.5 * np.abs(q - home).max(axis=0)
    test_limits = JointLimits(
        position_lower=home - (span if quantity == 'position' else wide),
        position_upper=home + (span if quantity == 'position' else wide),
        velocity=1.5 * np.abs(qd).max(axis=0) if quantity == 'velocity' else wide,
        acceleration=1.5 * np.abs(qdd).max(axis=0) if quantity == 'acceleration' else wide,
        torque=limits.torque,
    )
    check_limits(trajectory, test_limits, PERIOD_S)  # precondition: the design itself passes

    with pytest.raises(ConfigError, match=rf'exceeds the {quantity} limit of joint_\d at t = '):
        check_limits(scaled(trajectory, 2, 3.0), test_limits, PERIOD_S)


def test_tripled_segment_fails_the_real_limits(
    case: tuple[JointLimits, ExcitationTrajectory],
) -> None:
    limits, trajectory = case

    with pytest.raises(ConfigError, match=r'excitation exceeds the (position|velocity|accel)'):
        check_limits(scaled(trajectory, 1, 3.0), limits, PERIOD_S / 8)


def test_a_segment_that_does_not_start_at_home_is_refused_as_a_jump() -> None:
    # Probe 16 (C24): a design edited to hold joint_6 (its a, b zeroed, q0 left) was simulated
    # with 2.24 rad steps at every segment start.
    trajectory = designed('mabi_max100', 0)
    limits = robot('mabi_max100').limits
    segments = list(trajectory.segments)
    first = segments[0]
    a, b = first.a.copy(), first.b.copy()
    a[5], b[5] = 0.0, 0.0
    segments[0] = FourierSegment(a, b, first.q0, first.omega)
    held = replace(trajectory, segments=tuple(segments))
    if abs(first.q0[5] - trajectory.home[5]) < 1e-3:
        pytest.skip('this design starts joint_6 at home anyway')
    with pytest.raises(ConfigError, match=r'excitation position of joint_6 jumps by .* rad at t'):
        check_limits(held, limits, PERIOD_S / 8)


@pytest.mark.parametrize(
    ('home', 'match'),
    [
        pytest.param((3.0, 0.0, 0.0, 0.0, 0.0, 0.0), r' .*strictly inside .*: joint #1 3 rad',
                     id='on-the-upper-limit'),
        pytest.param((0.0, 0.0, -2.6, 0.0, 0.0, 0.0), r' .*strictly inside .*: joint #3 -2\.6 rad',
                     id='below-the-lower-limit'),
        pytest.param((0.0, 0.0, 0.0, 0.0, 0.0), r': 5 value\(s\) for 6 joints',
                     id='too-few-joints'),
    ],
)  # fmt: skip
def test_home_outside_the_position_limits_is_refused(home: tuple[float, ...], match: str) -> None:
    config = ExcitationConfig(duration_s=30, home=home)

    with pytest.raises(ConfigError, match=rf'^excitation\.home{match}'):
        design_excitation(config, robot('mabi_max100').limits, PERIOD_S, np.random.default_rng(0))


def test_explicit_home_is_where_the_segments_rest() -> None:
    home = (0.5, 0.2, -0.3, 1.0, -0.4, 2.0)
    config = ExcitationConfig(duration_s=30, home=home)

    trajectory = design_excitation(
        config, robot('mabi_max100').limits, PERIOD_S, np.random.default_rng(6)
    )

    np.testing.assert_array_equal(trajectory.home, home)
    q, qd, _ = trajectory.segments[0].evaluate(np.array([0.0, trajectory.period_s]))
    np.testing.assert_allclose(q, [home, home], atol=1e-9)
    np.testing.assert_allclose(qd, 0.0, atol=1e-9)
    q_all, _, _ = trajectory.evaluate(np.arange(0.0, trajectory.duration_s, PERIOD_S))
    assert np.all(q_all >= robot('mabi_max100').limits.position_lower)
    assert np.all(q_all <= robot('mabi_max100').limits.position_upper)


def test_dict_round_trip_through_json_evaluates_identically() -> None:
    trajectory = designed('panda', 4)
    t = np.random.default_rng(7).uniform(0.0, trajectory.duration_s, 5000)

    restored = ExcitationTrajectory.from_dict(json.loads(json.dumps(trajectory.to_dict())))

    assert len(restored.segments) == len(trajectory.segments)
    assert restored.duration_s == trajectory.duration_s
    for original, copy in zip(trajectory.evaluate(t), restored.evaluate(t), strict=True):
        np.testing.assert_allclose(copy, original, rtol=0, atol=0)


def test_same_seed_gives_identical_coefficients_and_another_seed_different_ones() -> None:
    limits = robot('mabi_max100').limits
    first = design_excitation(CONFIG, limits, PERIOD_S, np.random.default_rng(42))
    again = design_excitation(CONFIG, limits, PERIOD_S, np.random.default_rng(42))
    other = design_excitation(CONFIG, limits, PERIOD_S, np.random.default_rng(43))

    for one, two in zip(first.segments, again.segments, strict=True):
        np.testing.assert_array_equal(one.a, two.a)
        np.testing.assert_array_equal(one.b, two.b)
        np.testing.assert_array_equal(one.q0, two.q0)
    for one, two in zip(first.segments, other.segments, strict=True):
        assert not np.allclose(one.a, two.a)
        assert not np.allclose(one.b, two.b)
    # Segments differ from one another within one design, too.
    assert not np.allclose(first.segments[0].a, first.segments[1].a)


@pytest.mark.parametrize(
    ('key', 'value'),
    [
        ('duration_s', 0.0),
        ('duration_s', -10.0),
        ('base_frequency_hz', 0.0),
        ('harmonics', 0),
        ('harmonics', 11),
        ('position_fraction', 0.0),
        ('position_fraction', 1.5),
        ('velocity_fraction', 0.0),
        ('velocity_fraction', 1.01),
        ('acceleration_fraction', -0.2),
        ('rest_s', -0.1),
    ],
)
def test_excitation_config_rejects_out_of_range_values_naming_the_key(
    key: str, value: float
) -> None:
    with pytest.raises(ConfigError, match=rf'excitation\.{key}: value {value!r} is out of range'):
        ExcitationConfig(**{key: value})


def test_excitation_config_defaults_are_the_study_settings() -> None:
    config = ExcitationConfig()

    assert config.harmonics == 3
    assert config.base_frequency_hz == 0.04
    assert config.period_s == 25.0


def test_full_range_design_with_any_rest_time_is_accepted() -> None:
    config = ExcitationConfig(duration_s=60, position_fraction=1.0, rest_s=0.2345)
    limits = robot('mabi_max100').limits

    trajectory = design_excitation(config, limits, PERIOD_S, np.random.default_rng(0))

    q, _, _ = trajectory.evaluate(np.arange(0.0, trajectory.duration_s, PERIOD_S / 16))
    assert np.all(q >= limits.position_lower)
    assert np.all(q <= limits.position_upper)
