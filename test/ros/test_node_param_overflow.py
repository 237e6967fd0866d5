"""Every number a node parameter may hold converts to the integers the node uses (nanoseconds,
bytes) without overflow: huge values are refused where they enter, naming the key, and the
replay's span arithmetic stays in range whatever it is given. No ROS needed."""

from __future__ import annotations

import dataclasses
import sys
from typing import Any, get_type_hints

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.nodes.params import (
    PredictorNodeConfig,
    RecorderConfig,
    ReplayConfig,
    config_from_mapping,
    guard_config,
)
from id_learning.nodes.replay_plan import NS_PER_S

CONFIGS = (RecorderConfig, ReplayConfig, PredictorNodeConfig)
REQUIRED: dict[type, dict[str, Any]] = {ReplayConfig: {'bag': 'b'}, PredictorNodeConfig: {
    'artifact': 'a'}}  # fmt: skip
INT64_MAX = 2**63 - 1
#: A header stamp of today [ns], and a late one (2200).
TODAY_NS, LATE_NS = 1_767_225_600_000_000_000, 7_258_118_400_000_000_000


def _floats(cls: type) -> dict[str, st.SearchStrategy[float]]:
    """A strategy per float field: any finite value its schema declares allowed."""
    drawn = {}
    for item in dataclasses.fields(cls):
        if get_type_hints(cls)[item.name] is not float:
            continue
        low, high, low_open, high_open = item.metadata['range']
        drawn[item.name] = st.floats(
            min_value=-sys.float_info.max if low is None else low,
            max_value=sys.float_info.max if high is None else high,
            exclude_min=low_open and low is not None,
            exclude_max=high_open and high is not None,
            allow_nan=False,
            allow_infinity=False,
        )
    return drawn


def _config(cls: type, values: dict[str, float]) -> Any:
    try:
        return config_from_mapping(cls, {**REQUIRED.get(cls, {}), **values}, 'test')
    except ConfigError:
        assume(False)  # a rule between fields (a split below its floor): not this test's


@pytest.mark.parametrize('cls', CONFIGS, ids=lambda cls: cls.__name__)
def test_every_time_and_size_parameter_fits_int64_ns_and_bytes(cls: type) -> None:
    """Seconds [s] as nanoseconds, MiB as bytes: each declared range ends within int64."""

    @settings(max_examples=60, deadline=None)
    @given(st.fixed_dictionaries(_floats(cls)))
    def check(values: dict[str, float]) -> None:
        config = _config(cls, values)
        for name in values:
            value = getattr(config, name)
            if name.endswith('_s'):
                assert abs(round(value * NS_PER_S)) <= INT64_MAX, name
            elif name.endswith('_mib'):
                assert abs(round(value * (1 << 20))) <= INT64_MAX, name

    check()


@settings(max_examples=200, deadline=None)
@given(st.fixed_dictionaries(_floats(RecorderConfig)))
def test_recorder_split_settings_convert_for_any_declared_value(values: dict[str, float]) -> None:
    config = _config(RecorderConfig, values)
    for converted in (config.split_duration_ns, config.split_bytes):
        assert converted is None or 0 < converted <= INT64_MAX


@settings(max_examples=200, deadline=None)
@given(
    st.fixed_dictionaries(_floats(ReplayConfig)),
    st.sampled_from([0, TODAY_NS, LATE_NS]),
    st.integers(0, 10**12),
)
def test_replay_span_converts_for_any_declared_value(
    values: dict[str, float], origin: int, length: int
) -> None:
    from id_learning.nodes.replay_plan import span_keys

    config = _config(ReplayConfig, values)
    start, stop = span_keys(config.start_offset_s, config.duration_s, origin, origin + length)
    assert origin <= start <= INT64_MAX
    assert stop is None or start <= stop <= origin + length  # beyond the bag: to its end
    assert config.duration_s * NS_PER_S / config.rate <= 1e30  # the wall time is a number


def test_predictor_guard_settings_convert_for_any_declared_value(mabi: Any) -> None:
    @settings(max_examples=100, deadline=None)
    @given(st.fixed_dictionaries(_floats(PredictorNodeConfig)))
    def check(values: dict[str, float]) -> None:
        config = _config(PredictorNodeConfig, values)
        try:
            guards = guard_config(config, mabi)
        except ConfigError:  # acceleration_cutoff_hz above the robot's Nyquist frequency
            assume(False)
        assert 0 < guards.stale_after_ns <= INT64_MAX

    check()


@pytest.mark.parametrize(
    ('cls', 'values', 'key'),
    [
        (ReplayConfig, {'duration_s': 1e308}, 'duration_s'),  # probe Y11
        (ReplayConfig, {'start_offset_s': 1e308}, 'start_offset_s'),  # probe Y12
        (ReplayConfig, {'duration_s': 1e300, 'start_offset_s': 1e-300}, 'duration_s'),  # Y15
        (RecorderConfig, {'split_duration_s': 1e308}, 'split_duration_s'),  # probe R24
        (RecorderConfig, {'split_size_mib': 1e308}, 'split_size_mib'),  # probe R25
        (ReplayConfig, {'wait_timeout_s': 1e308}, 'wait_timeout_s'),
        (PredictorNodeConfig, {'log_throttle_s': 1e308}, 'log_throttle_s'),
        (PredictorNodeConfig, {'stale_log_period_s': 1e308}, 'stale_log_period_s'),
        (PredictorNodeConfig, {'adaptation_time_constant_s': 1e308}, 'adaptation_time_constant_s'),
    ],
)
def test_a_huge_value_is_refused_naming_the_key_and_its_range(
    cls: type, values: dict[str, float], key: str
) -> None:
    with pytest.raises(
        ConfigError, match=rf'test: {key}: must be a finite number in [(\[].*got 1e'
    ):
        config_from_mapping(cls, {**REQUIRED.get(cls, {}), **values}, 'test')


def test_a_rate_too_slow_to_finish_is_refused_naming_the_floor() -> None:
    """Probe Y08: rate 1e-9 played one cycle, then would have taken 30 years for the next."""
    with pytest.raises(ConfigError, match=r'test: rate: must be a finite number in \[0.001, '):
        config_from_mapping(ReplayConfig, {'bag': 'b', 'rate': 1e-9}, 'test')
    assert config_from_mapping(ReplayConfig, {'bag': 'b', 'rate': 1e-3}, 'test').rate == 1e-3


@pytest.mark.parametrize(
    ('offset_s', 'duration_s', 'expected'),
    [
        (0.0, 1e308, (TODAY_NS, None)),  # beyond the bag: to its end
        (1e-300, 1e300, (TODAY_NS, None)),
        (1.0, 2.0, (TODAY_NS + NS_PER_S, TODAY_NS + 3 * NS_PER_S)),
        (1.0, 0.0, (TODAY_NS + NS_PER_S, None)),  # 0: to the end
        (1e308, 1.0, (TODAY_NS + 10 * NS_PER_S + 1, None)),  # after the bag: nothing in it
        (float('inf'), float('inf'), (TODAY_NS + 10 * NS_PER_S + 1, None)),
    ],
)
def test_span_keys_stay_within_the_bag_whatever_they_are_given(
    offset_s: float, duration_s: float, expected: tuple[int, int | None]
) -> None:
    from id_learning.nodes.replay_plan import span_keys

    assert span_keys(offset_s, duration_s, TODAY_NS, TODAY_NS + 10 * NS_PER_S) == expected
