"""The bag's stamps: an absolute time column's own time, else re-based; the summary says which."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.bag import read_joint_states
from id_learning.dataset.import_mapping import ResamplePolicy
from id_learning.dataset.import_stamps import absolute_start_ns
from id_learning.dataset.importer import (
    DEFAULT_START_NS,
    ColumnSpec,
    ImportMapping,
    JointColumns,
    import_log,
    import_logs,
)
from id_learning.errors import ConfigError, DatasetError

NEW_YEAR_2026_S = 1_767_225_600  # 2026-01-01T00:00:00Z
PERIOD_NS = 8_000_000
UNIT_NS = {'s': 10**9, 'ms': 10**6, 'us': 10**3, 'ns': 1}


def mapping(unit: str = 's', offset: float = 0.0, **options: object) -> ImportMapping:
    joints = tuple(
        JointColumns(
            f'joint_{j}',
            ColumnSpec(f'q{j}', 'rad'),
            ColumnSpec(f'v{j}', 'rad/s'),
            current=ColumnSpec(f'i{j}', 'A'),
        )
        for j in (1, 2)
    )
    time = ColumnSpec('t', unit, offset=offset)
    return ImportMapping(joints=joints, time=time, **options)  # type: ignore[arg-type]


def write_log(path: Path, times: np.ndarray, seed: int = 0) -> Path:
    """A log at ``times`` (as written, any unit): a smooth motion of two joints, noisy currents."""
    n = len(times)
    rng = np.random.default_rng(seed)
    phase = 2 * np.pi * 0.5 * 0.008 * np.arange(n) + seed
    rows = np.column_stack(
        [
            0.3 * np.sin(phase),
            0.2 * np.cos(phase),
            0.3 * np.pi * np.cos(phase),
            -0.2 * np.pi * np.sin(phase),
            rng.normal(0.0, 0.5, size=(n, 2)),
        ]
    )
    lines = ['t,q1,q2,v1,v2,i1,i2']
    cells = np.column_stack([times, rows])
    lines += [','.join(repr(float(x)) for x in row) for row in cells]
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def stamps(bag: Path) -> np.ndarray:
    return read_joint_states(bag, '/joint_states').stamps_ns


@pytest.mark.parametrize('unit', ['s', 'ms', 'us', 'ns'])
def test_an_epoch_time_column_keeps_the_logs_time_in_any_unit(tmp_path: Path, unit: str) -> None:
    scale = 10**9 // UNIT_NS[unit]  # units per second
    times = NEW_YEAR_2026_S * float(scale) + 0.008 * scale * np.arange(200)
    report = import_log(write_log(tmp_path / 'log.csv', times), mapping(unit), tmp_path / 'bag')
    expected = NEW_YEAR_2026_S * 10**9 + PERIOD_NS * np.arange(200)
    np.testing.assert_allclose(stamps(tmp_path / 'bag'), expected, rtol=0, atol=1000)
    assert report.time_base == 'absolute'
    assert (
        "stamps keep the time column's absolute time: first sample at 2026-01-01T00:00:00"
        in report.summary()
    )


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    start_s=st.integers(978_307_200, 2_100_000_000),  # 2001 to 2036
    jitter_ms=st.lists(st.floats(-1.5, 1.5), min_size=50, max_size=50),
)
def test_snapped_stamps_stay_within_the_jitter_tolerance_of_the_logs_times(
    start_s: int, jitter_ms: list[float]
) -> None:
    times_ms = start_s * 1e3 + 8.0 * np.arange(50) + np.array(jitter_ms)
    with tempfile.TemporaryDirectory() as folder:
        log = write_log(Path(folder) / 'log.csv', times_ms)
        grid = ResamplePolicy(period_s=0.008)  # not the median step, which the jitter moves
        import_log(log, mapping('ms', resample=grid), Path(folder) / 'bag')
        got = stamps(Path(folder) / 'bag')
    # Each stamp is its row's time moved onto the 8 ms grid by at most the tolerance (2 ms).
    logged_ns = times_ms * 1e6
    assert np.abs(got - logged_ns).max() <= 0.25 * PERIOD_NS + 2e3
    assert (np.diff(got) % PERIOD_NS == 0).all()


def test_a_relative_time_column_is_re_based_and_the_summary_says_to_what(tmp_path: Path) -> None:
    log = write_log(tmp_path / 'log.csv', 12.0 + 0.008 * np.arange(100))
    report = import_log(log, mapping(), tmp_path / 'bag')
    assert stamps(tmp_path / 'bag')[0] == DEFAULT_START_NS
    assert report.time_base == 'relative'
    assert report.summary().splitlines()[1] == (
        '  stamps re-based (the time column starts at 12 s, not an epoch time): first sample at '
        '2023-11-14T22:13:20.000000Z'
    )


def test_an_offset_gives_a_relative_time_column_its_absolute_base(tmp_path: Path) -> None:
    log = write_log(tmp_path / 'log.csv', 0.008 * np.arange(100))
    report = import_log(log, mapping(offset=NEW_YEAR_2026_S), tmp_path / 'bag')
    assert stamps(tmp_path / 'bag')[0] == NEW_YEAR_2026_S * 10**9
    assert report.time_base == 'absolute'


def test_a_start_asked_for_re_bases_an_absolute_time_column(tmp_path: Path) -> None:
    log = write_log(tmp_path / 'log.csv', NEW_YEAR_2026_S + 0.008 * np.arange(100))
    report = import_log(log, mapping(), tmp_path / 'bag', start_ns=5 * 10**9)
    assert stamps(tmp_path / 'bag')[0] == 5 * 10**9
    assert 'stamps re-based (the start asked for): first sample at 1970-01-01T00:00:05' in (
        report.summary()
    )


def test_absolute_files_are_put_in_time_order_at_their_own_times(tmp_path: Path) -> None:
    later = write_log(tmp_path / 'a_later.csv', NEW_YEAR_2026_S + 60 + 0.008 * np.arange(100))
    first = write_log(tmp_path / 'b_first.csv', NEW_YEAR_2026_S + 0.008 * np.arange(150), 1)
    reports = import_logs([later, first], mapping(), tmp_path / 'bag')
    got = stamps(tmp_path / 'bag')
    start = NEW_YEAR_2026_S * 10**9
    expected = np.concatenate(
        [start + PERIOD_NS * np.arange(150), start + 60 * 10**9 + PERIOD_NS * np.arange(100)]
    )
    np.testing.assert_array_equal(got, expected)
    assert [r.start_ns for r in reports] == [start + 60 * 10**9, start]


def test_absolute_files_that_overlap_in_time_are_refused_naming_both(tmp_path: Path) -> None:
    a = write_log(tmp_path / 'a.csv', NEW_YEAR_2026_S + 0.008 * np.arange(200))
    b = write_log(tmp_path / 'b.csv', NEW_YEAR_2026_S + 1.0 + 0.008 * np.arange(200), seed=1)
    with pytest.raises(
        DatasetError,
        match=r'import: .*b\.csv \(2026-01-01T00:00:01\.000000Z to 2026-01-01T00:00:02\.592000Z\) '
        r'overlaps .*a\.csv \(to 2026-01-01T00:00:01\.592000Z\) in time',
    ):
        import_logs([a, b], mapping(), tmp_path / 'bag')


def test_a_row_repeated_at_a_file_change_is_kept_once(tmp_path: Path, caplog) -> None:
    a = write_log(tmp_path / 'a.csv', NEW_YEAR_2026_S + 0.008 * np.arange(200))
    # The logger writes a's last row again as b's first (another seed: its own values).
    b = write_log(tmp_path / 'b.csv', NEW_YEAR_2026_S + 0.008 * np.arange(199, 400), seed=1)
    import_logs([a, b], mapping(), tmp_path / 'bag')
    got = stamps(tmp_path / 'bag')
    np.testing.assert_array_equal(got, NEW_YEAR_2026_S * 10**9 + PERIOD_NS * np.arange(400))
    assert 'b.csv repeats the last 1 sample time(s) of' in caplog.text


def test_an_absolute_file_among_relative_ones_is_re_based_saying_why(tmp_path: Path) -> None:
    absolute = write_log(tmp_path / 'a.csv', NEW_YEAR_2026_S + 0.008 * np.arange(100))
    relative = write_log(tmp_path / 'b.csv', 0.008 * np.arange(100), seed=1)
    reports = import_logs([absolute, relative], mapping(), tmp_path / 'bag')
    assert [r.time_base for r in reports] == ['mixed', 'relative']
    assert "re-based (the time column is absolute here but not in every file's)" in (
        reports[0].summary()
    )


@pytest.mark.parametrize(
    ('first', 'unit', 'expected'),
    [
        (0.0, 's', None),
        (3.6e6, 's', None),  # a controller up for 41 days
        (946_684_800.0, 's', 946_684_800 * 10**9),  # 2000-01-01
        (1_767_225_600_123.0, 'ms', 1_767_225_600_123_000_000),
        (2_147_483_647.0, 's', 2_147_483_647 * 10**9),  # 2038-01-19, the last stamp's second
        (2_147_483_648.0, 's', None),  # beyond what a message stamp holds: taken as relative
    ],
)
def test_an_absolute_time_is_one_of_this_century(
    first: float, unit: str, expected: int | None
) -> None:
    assert absolute_start_ns(first, mapping(unit)) == expected


@pytest.mark.parametrize('period_s', [0.010, 0.0081, 0.004])
def test_a_fixed_period_off_the_robots_ipo_period_is_refused(
    tmp_path: Path, mabi, period_s: float
) -> None:
    # Probe 15 (A63): period_s 0.010 for an 8 ms robot gave a 10 ms bag without a word.

    rows = np.outer(np.arange(20), np.full(6, 0.002))  # a slow ramp on every joint
    csv = tmp_path / 'log.csv'
    np.savetxt(csv, rows, delimiter=',', header=','.join(mabi.joints), comments='')

    def fixed(period: float) -> ImportMapping:
        joints = tuple(JointColumns(name, ColumnSpec(name, 'rad')) for name in mabi.joints)
        return ImportMapping(period_s=period, joints=joints)

    with pytest.raises(ConfigError, match=rf'period_s {period_s:g} s is not the IPO period 0.008'):
        import_log(csv, fixed(period_s), tmp_path / 'bag', robot=mabi)
    assert not (tmp_path / 'bag').exists()
    import_log(csv, fixed(0.008), tmp_path / 'ok', robot=mabi)
