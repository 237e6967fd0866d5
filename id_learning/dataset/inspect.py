"""Inspect a bag without judging it: timing, gaps, value ranges, limits and contract, as a report.

Unlike ``load_recording``, nothing here rejects a bag for its contents: NaN values, gaps, repeated
or backward stamps, joint-name changes and mismatched contract topics are counted and reported.
Only a bag that cannot be read at all raises ``BagError``.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

import numpy as np
from rosbags.serde import SerdeError

from id_learning.bag import JOINT_STATE, JointStateSeries, bag_info, decode_joint_state, iter_raw
from id_learning.dataset.recording import Recording
from id_learning.errors import BagError, ConfigError
from id_learning.robot.config import RobotConfig, TopicConfig

__all__ = [
    'BagReport',
    'ContractReport',
    'FieldStats',
    'Gap',
    'JointReport',
    'TimingReport',
    'TopicReport',
    'inspect_bag',
    'plot_report',
    'render_report',
]

_LOG = logging.getLogger(__name__)

NS_PER_S = 1_000_000_000
GAP_PERIODS = 1.5
"""A step longer than this many nominal periods is a gap."""
MAX_LISTED = 10
"""How many gaps, repeated and backward stamps a report lists (it counts all of them)."""
FIELDS = ('position', 'velocity', 'effort')


# -- report types ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Gap:
    """A step between two samples longer than ``GAP_PERIODS`` nominal periods.

    Attributes:
        sample: index of the first sample after the gap, on its topic.
        stamp_ns: that sample's time stamp [ns].
        periods: the step in nominal periods (1.0 is a regular step).
    """

    sample: int
    stamp_ns: int
    periods: float


@dataclass(frozen=True)
class TimingReport:
    """Time stamps of one topic.

    Jitter is measured over the regular steps only (0 < step <= ``GAP_PERIODS`` periods); gaps,
    repeated and backward stamps are counted apart.

    Attributes:
        time_base: 'header' (JointState header stamps) or 'log' (bag receive times).
        rate_hz: mean rate, (count - 1) / time span [Hz]; None with fewer than two distinct stamps.
        nominal_period_s: the period steps are compared with [s]: the given period, the robot's
            IPO period, or the median step.
        median_period_s: median of the positive steps [s].
        jitter_std_ms: standard deviation of the regular steps [ms].
        jitter_p99_ms: 99th percentile of |step - nominal period| over the regular steps [ms].
        gap_count: number of gaps.
        gaps: the first ``MAX_LISTED`` gaps.
        repeated_count: steps of zero (a stamp repeats).
        repeated: sample indices of the first ``MAX_LISTED`` repeated stamps.
        backward_count: negative steps (a stamp goes backwards).
        backward: sample indices of the first ``MAX_LISTED`` backward stamps.
    """

    time_base: Literal['header', 'log']
    rate_hz: float | None
    nominal_period_s: float | None
    median_period_s: float | None
    jitter_std_ms: float | None
    jitter_p99_ms: float | None
    gap_count: int
    gaps: tuple[Gap, ...]
    repeated_count: int
    repeated: tuple[int, ...]
    backward_count: int
    backward: tuple[int, ...]


@dataclass(frozen=True)
class FieldStats:
    """One field (position, velocity or effort) of one joint, over the finite values.

    Attributes:
        minimum, maximum, mean: in the field's unit; None when no value is finite.
        non_finite: number of NaN or infinite values.
    """

    minimum: float | None
    maximum: float | None
    mean: float | None
    non_finite: int


@dataclass(frozen=True)
class JointReport:
    """Value ranges of one joint on one JointState topic.

    Attributes:
        name: joint name.
        position, velocity, effort: statistics, or None when the messages leave the field empty.
        position_outside_limits: fraction of samples outside the robot's position limits [-];
            None without a robot, a position field, or a joint of that name in the robot.
        velocity_outside_limits: fraction of samples with |velocity| above the robot's limit [-].
    """

    name: str
    position: FieldStats | None
    velocity: FieldStats | None
    effort: FieldStats | None
    position_outside_limits: float | None = None
    velocity_outside_limits: float | None = None


@dataclass(frozen=True)
class TopicReport:
    """One topic of a bag.

    Attributes:
        name: topic name.
        msgtype: message type, e.g. 'sensor_msgs/msg/JointState'.
        count: messages read.
        timing: time stamp statistics.
        joints: per-joint statistics (JointState topics only; empty otherwise).
        undecodable: messages whose bytes do not deserialize (JointState topics).
        inconsistent: messages whose joint names or array lengths differ from the first message;
            they count in the timing but not in the joint statistics.
        first_inconsistent: sample index of the first such message, or None.
    """

    name: str
    msgtype: str
    count: int
    timing: TimingReport
    joints: tuple[JointReport, ...] = ()
    undecodable: int = 0
    inconsistent: int = 0
    first_inconsistent: int | None = None


@dataclass(frozen=True)
class ContractReport:
    """Whether the bag holds the contract's two topics with matching stamps and joints.

    Attributes:
        joint_states: the contract's joint state topic.
        motor_currents: the contract's motor current topic.
        missing: contract topics the bag lacks (or holds with another type than JointState).
        stamps_match: both topics carry the same header stamps, sample for sample; None when a
            topic is missing.
        first_mismatch: first sample index where the stamps differ (or the shorter topic ends).
        names_match: both topics name the same joints; None when a topic is missing or empty.
    """

    joint_states: str
    motor_currents: str
    missing: tuple[str, ...]
    stamps_match: bool | None
    first_mismatch: int | None
    names_match: bool | None

    @property
    def is_met(self) -> bool:
        """Whether both topics are there with matching stamps and joint names."""
        return not self.missing and bool(self.stamps_match) and bool(self.names_match)


@dataclass(frozen=True, eq=False)
class BagReport:
    """What ``inspect_bag`` found.

    Attributes:
        path: the bag folder.
        storage: storage format ('mcap' or 'other').
        files: data file names.
        start_ns: first log time [ns since epoch]; start_iso: the same in ISO 8601, UTC.
        duration_s: log-time span [s].
        message_count: messages read on all topics.
        robot_name: the robot the bag was checked against, or None.
        topics: one report per topic.
        contract: the contract topics check.
        series: the stacked samples of each JointState topic (consistent messages only), kept
            for ``plot_report``.
    """

    path: Path
    storage: str
    files: tuple[str, ...]
    start_ns: int
    start_iso: str
    duration_s: float
    message_count: int
    robot_name: str | None
    topics: tuple[TopicReport, ...]
    contract: ContractReport
    series: Mapping[str, JointStateSeries] = field(default_factory=dict, repr=False)

    def topic(self, name: str) -> TopicReport:
        """Return the report of one topic.

        Raises:
            BagError: the bag has no such topic (lists those it has).
        """
        for topic in self.topics:
            if topic.name == name:
                return topic
        raise BagError(
            f'{self.path}: no topic {name}; the bag has {[t.name for t in self.topics]}'
        )

    @property
    def problems(self) -> tuple[str, ...]:
        """One line per finding that ``load_recording`` would reject or a human should check."""
        lines: list[str] = []
        for topic in self.topics:
            lines += _topic_problems(topic)
        contract = self.contract
        if contract.missing:
            lines.append(f'contract: missing JointState topic(s) {list(contract.missing)}')
        elif contract.stamps_match is False:
            lines.append(
                f'contract: {contract.motor_currents} stamps differ from {contract.joint_states} '
                f'from sample {contract.first_mismatch} on'
            )
        if contract.names_match is False:
            lines.append(
                f'contract: {contract.motor_currents} and {contract.joint_states} name '
                'different joints'
            )
        return tuple(lines)


def _topic_problems(topic: TopicReport) -> list[str]:
    lines: list[str] = []
    timing = topic.timing
    if topic.count == 0:
        lines.append(f'{topic.name}: no messages')
    if timing.gap_count:
        first = timing.gaps[0]
        lines.append(
            f'{topic.name}: {timing.gap_count} gap(s) > {GAP_PERIODS:g} periods, the first before '
            f'sample {first.sample} ({first.periods:.1f} periods)'
        )
    if timing.repeated_count:
        lines.append(
            f'{topic.name}: {timing.repeated_count} repeated stamp(s), the first at sample '
            f'{timing.repeated[0]}'
        )
    if timing.backward_count:
        lines.append(
            f'{topic.name}: {timing.backward_count} stamp(s) going backwards, the first at sample '
            f'{timing.backward[0]}'
        )
    if topic.undecodable:
        lines.append(f'{topic.name}: {topic.undecodable} message(s) do not deserialize')
    if topic.inconsistent:
        lines.append(
            f'{topic.name}: {topic.inconsistent} message(s) change joint names or array lengths, '
            f'the first at sample {topic.first_inconsistent}'
        )
    for joint in topic.joints:
        for key in FIELDS:
            stats: FieldStats | None = getattr(joint, key)
            if stats is not None and stats.non_finite:
                lines.append(
                    f'{topic.name}: {joint.name} {key}: {stats.non_finite} non-finite value(s)'
                )
        for key, fraction in (
            ('position', joint.position_outside_limits),
            ('velocity', joint.velocity_outside_limits),
        ):
            if fraction:
                lines.append(
                    f'{topic.name}: {joint.name} {key} outside the robot limits in '
                    f'{100 * fraction:.2f} % of samples'
                )
    return lines


# -- analysis -------------------------------------------------------------------------------------
def _timing(
    stamps_ns: np.ndarray,
    sample_index: np.ndarray,
    nominal_period_s: float | None,
    time_base: Literal['header', 'log'],
) -> TimingReport:
    """Timing statistics of stamps in bag order; sample_index maps positions to sample indices."""
    steps = np.diff(stamps_ns)
    positive = steps[steps > 0]
    median = float(np.median(positive)) * 1e-9 if positive.size else None
    nominal = nominal_period_s if nominal_period_s is not None else median
    span = int(stamps_ns.max() - stamps_ns.min()) if stamps_ns.size else 0
    rate = (stamps_ns.size - 1) / (span * 1e-9) if span > 0 else None

    gaps: tuple[Gap, ...] = ()
    gap_count = 0
    jitter_std = jitter_p99 = None
    if nominal is not None:
        nominal_ns = nominal * 1e9
        is_gap = steps > GAP_PERIODS * nominal_ns
        gap_at = np.flatnonzero(is_gap) + 1
        gap_count = int(gap_at.size)
        gaps = tuple(
            Gap(int(sample_index[k]), int(stamps_ns[k]), float(steps[k - 1] / nominal_ns))
            for k in gap_at[:MAX_LISTED]
        )
        regular = steps[(steps > 0) & ~is_gap]
        if regular.size:
            jitter_std = float(np.std(regular)) * 1e-6
            jitter_p99 = float(np.percentile(np.abs(regular - nominal_ns), 99)) * 1e-6
    repeated_at = np.flatnonzero(steps == 0) + 1
    backward_at = np.flatnonzero(steps < 0) + 1
    return TimingReport(
        time_base=time_base,
        rate_hz=rate,
        nominal_period_s=nominal,
        median_period_s=median,
        jitter_std_ms=jitter_std,
        jitter_p99_ms=jitter_p99,
        gap_count=gap_count,
        gaps=gaps,
        repeated_count=int(repeated_at.size),
        repeated=tuple(int(sample_index[k]) for k in repeated_at[:MAX_LISTED]),
        backward_count=int(backward_at.size),
        backward=tuple(int(sample_index[k]) for k in backward_at[:MAX_LISTED]),
    )


def _field_stats(values: np.ndarray) -> FieldStats:
    """Statistics of one column (N,) over its finite values."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return FieldStats(None, None, None, int(values.size))
    return FieldStats(
        minimum=float(finite.min()),
        maximum=float(finite.max()),
        mean=float(finite.mean()),
        non_finite=int(values.size - finite.size),
    )


def _joint_reports(series: JointStateSeries, robot: RobotConfig | None) -> tuple[JointReport, ...]:
    reports = []
    for column, name in enumerate(series.names):
        stats: dict[str, FieldStats | None] = {}
        for key in FIELDS:
            array = getattr(series, key)
            stats[key] = None if array is None else _field_stats(array[:, column])
        position_out = velocity_out = None
        if robot is not None and name in robot.joints:
            joint = robot.joints.index(name)
            limits = robot.limits
            # NaN compares False, so non-finite samples count as inside; they are reported apart.
            if series.position is not None and len(series.position):
                q = series.position[:, column]
                outside = (q < limits.position_lower[joint]) | (q > limits.position_upper[joint])
                position_out = float(np.mean(outside))
            if series.velocity is not None and len(series.velocity):
                v = series.velocity[:, column]
                velocity_out = float(np.mean(np.abs(v) > limits.velocity[joint]))
        reports.append(
            JointReport(
                name=name,
                position=stats['position'],
                velocity=stats['velocity'],
                effort=stats['effort'],
                position_outside_limits=position_out,
                velocity_outside_limits=velocity_out,
            )
        )
    return tuple(reports)


@dataclass
class _JointStateTopic:
    """Accumulates the decoded messages of one JointState topic."""

    topic: str
    names: tuple[str, ...] | None = None
    lengths: dict[str, int] = field(default_factory=dict)
    all_stamps: list[int] = field(default_factory=list)
    all_index: list[int] = field(default_factory=list)
    stamps: list[int] = field(default_factory=list)
    logs: list[int] = field(default_factory=list)
    rows: dict[str, list[np.ndarray]] = field(default_factory=lambda: {key: [] for key in FIELDS})
    undecodable: int = 0
    inconsistent: int = 0
    first_inconsistent: int | None = None

    def add(self, index: int, log_ns: int, data: bytes) -> None:
        try:
            msg = decode_joint_state(data)
        except (SerdeError, ValueError, IndexError, KeyError, struct.error):
            # Damaged bytes are a finding here, not an error: count them and go on.
            self.undecodable += 1
            return
        self.all_stamps.append(msg.stamp_ns)
        self.all_index.append(index)
        if self.names is None:
            self.names = msg.name
            self.lengths = {key: len(getattr(msg, key)) for key in FIELDS}
        consistent = msg.name == self.names and all(
            len(getattr(msg, key)) == length and length in (0, len(self.names))
            for key, length in self.lengths.items()
        )
        if not consistent:
            self.inconsistent += 1
            if self.first_inconsistent is None:
                self.first_inconsistent = index
            return
        self.stamps.append(msg.stamp_ns)
        self.logs.append(log_ns)
        for key, rows in self.rows.items():
            if self.lengths[key]:
                rows.append(np.asarray(getattr(msg, key), dtype=np.float64))

    def series(self) -> JointStateSeries:
        names = self.names or ()

        def stacked(key: str) -> np.ndarray | None:
            if not self.lengths.get(key):
                return None
            rows = self.rows[key]
            return np.vstack(rows) if rows else np.empty((0, len(names)))

        return JointStateSeries(
            topic=self.topic,
            stamps_ns=np.array(self.stamps, dtype=np.int64),
            log_ns=np.array(self.logs, dtype=np.int64),
            names=names,
            position=stacked('position'),
            velocity=stacked('velocity'),
            effort=stacked('effort'),
        )


def _iso_utc(stamp_ns: int) -> str:
    seconds, rest = divmod(stamp_ns, NS_PER_S)
    moment = datetime.fromtimestamp(seconds, UTC).replace(microsecond=rest // 1000)
    return moment.isoformat(timespec='microseconds').replace('+00:00', 'Z')


def _contract(
    topics: TopicConfig,
    msgtypes: Mapping[str, str],
    decoded: Mapping[str, _JointStateTopic],
) -> ContractReport:
    names = (topics.joint_states, topics.motor_currents)
    missing = tuple(name for name in names if msgtypes.get(name) != JOINT_STATE)
    if missing:
        return ContractReport(*names, missing, None, None, None)
    states, currents = decoded[topics.joint_states], decoded[topics.motor_currents]
    a = np.array(states.all_stamps, dtype=np.int64)
    b = np.array(currents.all_stamps, dtype=np.int64)
    size = min(a.size, b.size)
    differ = np.flatnonzero(a[:size] != b[:size])
    if differ.size:
        first: int | None = int(differ[0])
    else:
        first = None if a.size == b.size else size
    names_match = (
        None if states.names is None or currents.names is None else states.names == currents.names
    )
    return ContractReport(*names, (), first is None, first, names_match)


def inspect_bag(
    path: Path | str,
    robot: RobotConfig | None = None,
    period_s: float | None = None,
) -> BagReport:
    """Read every message of a bag and report timing, value ranges, limits and the contract.

    JointState topics are timed by their header stamps, other topics by log times. Steps of
    JointState topics are compared with ``period_s``, else the robot's IPO period, else the
    median step; other topics always use their median step.

    Args:
        path: the rosbag2 folder.
        robot: robot to check joint limits and contract topic names against; without one the
            contract topics are '/joint_states' and '/motor_currents'.
        period_s: nominal sample period [s]; overrides the robot's IPO period.

    Returns:
        The report; samples a validated load would reject are counted, never raised.

    Raises:
        BagError: the bag is missing, incomplete, truncated or corrupt (cannot be read at all).
        ConfigError: period_s is not positive.
    """
    path = Path(path)
    if period_s is not None and not period_s > 0:
        raise ConfigError(f'period_s must be > 0 s, got {period_s!r}')
    info = bag_info(path)
    nominal = period_s if period_s is not None else (robot.ipo_period_s if robot else None)
    msgtypes = {topic.name: topic.msgtype for topic in info.topics}
    names = [topic.name for topic in info.topics]
    decoded = {
        name: _JointStateTopic(name) for name, kind in msgtypes.items() if kind == JOINT_STATE
    }
    log_times: dict[str, list[int]] = {name: [] for name in names}
    for topic, log_ns, data in iter_raw(path, names):
        index = len(log_times[topic])
        log_times[topic].append(log_ns)
        if topic in decoded:
            decoded[topic].add(index, log_ns, data)

    reports = []
    series: dict[str, JointStateSeries] = {}
    for name in names:
        count = len(log_times[name])
        if name in decoded:
            acc = decoded[name]
            timing = _timing(
                np.array(acc.all_stamps, dtype=np.int64),
                np.array(acc.all_index, dtype=np.int64),
                nominal,
                'header',
            )
            series[name] = acc.series()
            reports.append(
                TopicReport(
                    name=name,
                    msgtype=JOINT_STATE,
                    count=count,
                    timing=timing,
                    joints=_joint_reports(series[name], robot),
                    undecodable=acc.undecodable,
                    inconsistent=acc.inconsistent,
                    first_inconsistent=acc.first_inconsistent,
                )
            )
        else:
            stamps = np.array(log_times[name], dtype=np.int64)
            timing = _timing(stamps, np.arange(count), None, 'log')
            reports.append(TopicReport(name, msgtypes[name], count, timing))

    report = BagReport(
        path=path,
        storage=info.storage,
        files=info.files,
        start_ns=info.start_ns,
        start_iso=_iso_utc(info.start_ns),
        duration_s=info.duration_ns * 1e-9,
        message_count=sum(len(times) for times in log_times.values()),
        robot_name=robot.name if robot else None,
        topics=tuple(reports),
        contract=_contract(robot.topics if robot else TopicConfig(), msgtypes, decoded),
        series=series,
    )
    _LOG.debug('%s: %d messages on %d topics inspected', path, report.message_count, len(names))
    return report


# -- text -----------------------------------------------------------------------------------------
def _table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str) -> list[str]:
    """Align columns, align[i] being 'l' (text) or 'r' (numbers) for column i."""
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        parts = [
            cell.ljust(width) if side == 'l' else cell.rjust(width)
            for cell, width, side in zip(cells, widths, align, strict=True)
        ]
        return ('  ' + '  '.join(parts)).rstrip()

    return [line(header), '  ' + '  '.join('-' * width for width in widths), *map(line, rows)]


def _number(value: float | None, digits: int = 3) -> str:
    return '-' if value is None else f'{value:.{digits}f}'


def _percent(fraction: float | None) -> str:
    return '-' if fraction is None else f'{100 * fraction:.2f} %'


def render_report(report: BagReport) -> str:
    """Format a report as aligned plain text for a terminal."""
    timing_rows = []
    for topic in report.topics:
        timing = topic.timing
        jitter = (
            '-'
            if timing.jitter_std_ms is None
            else f'{timing.jitter_std_ms:.3f} / {_number(timing.jitter_p99_ms)}'
        )
        period = None if timing.median_period_s is None else timing.median_period_s * 1e3
        timing_rows.append(
            [
                topic.name,
                topic.msgtype,
                str(topic.count),
                timing.time_base,
                _number(timing.rate_hz),
                _number(period),
                jitter,
                str(timing.gap_count),
                str(timing.repeated_count),
                str(timing.backward_count),
            ]
        )
    lines = [
        f'bag       {report.path}',
        f'storage   {report.storage}, {len(report.files)} file(s): {", ".join(report.files)}',
        f'start     {report.start_iso} ({report.start_ns} ns)',
        f'duration  {report.duration_s:.3f} s, {report.message_count} messages',
        f'robot     {report.robot_name or "-"}',
        '',
        'topics',
        *_table(
            [
                'topic',
                'type',
                'count',
                'stamps',
                'rate [Hz]',
                'period [ms]',
                'jitter std / p99 [ms]',
                'gaps',
                'repeated',
                'backward',
            ],
            timing_rows,
            'llrlrrrrrr',
        ),
    ]
    for topic in report.topics:
        timing = topic.timing
        if timing.gap_count:
            nominal_ms = (timing.nominal_period_s or 0.0) * 1e3
            listed = f', first {MAX_LISTED} listed' if timing.gap_count > MAX_LISTED else ''
            lines += [
                '',
                f'gaps on {topic.name} ({timing.gap_count}, nominal period {nominal_ms:.3f} ms'
                f'{listed})',
                *_table(
                    ['before sample', 'stamp [ns]', 'periods'],
                    [[str(g.sample), str(g.stamp_ns), f'{g.periods:.2f}'] for g in timing.gaps],
                    'rrr',
                ),
            ]
        for label, count, samples in (
            ('repeated stamps', timing.repeated_count, timing.repeated),
            ('backward stamps', timing.backward_count, timing.backward),
        ):
            if count:
                listed = ', '.join(map(str, samples)) + (', ...' if count > len(samples) else '')
                lines += ['', f'{label} on {topic.name} ({count}) at samples {listed}']
        if topic.joints:
            rows = []
            for joint in topic.joints:
                for key in FIELDS:
                    stats: FieldStats | None = getattr(joint, key)
                    if stats is None:
                        continue
                    limit = {
                        'position': joint.position_outside_limits,
                        'velocity': joint.velocity_outside_limits,
                    }.get(key)
                    rows.append(
                        [
                            joint.name,
                            key,
                            _number(stats.minimum, 4),
                            _number(stats.maximum, 4),
                            _number(stats.mean, 4),
                            str(stats.non_finite),
                            _percent(limit),
                        ]
                    )
            lines += [
                '',
                f'joints on {topic.name}',
                *_table(
                    ['joint', 'field', 'min', 'max', 'mean', 'non-finite', 'outside limits'],
                    rows,
                    'llrrrrr',
                ),
            ]
    contract = report.contract
    pair = f'{contract.joint_states} / {contract.motor_currents}'
    if contract.missing:
        verdict = f'missing {", ".join(contract.missing)}'
    elif contract.stamps_match:
        verdict = 'stamps match sample for sample'
    else:
        verdict = f'stamps differ from sample {contract.first_mismatch} on'
    if contract.names_match is False:
        verdict += '; joint names differ'
    problems = report.problems
    lines += [
        '',
        f'contract  {pair}: {verdict}',
        '',
        f'problems  {len(problems) or "none"}',
        *(f'  - {problem}' for problem in problems),
    ]
    return '\n'.join(lines) + '\n'


# -- plot -----------------------------------------------------------------------------------------
def _envelope(t: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Decimate (N,) times and (N, n) values to at most max_points per line.

    Keeps each bucket's minimum and maximum, so that spikes survive, and NaN only where a whole
    bucket is NaN.
    """
    if len(t) <= max_points:
        return t, y
    buckets = max(max_points // 2, 1)
    starts = np.linspace(0, len(t), buckets, endpoint=False).astype(np.int64)
    low = np.fmin.reduceat(y, starts, axis=0)
    high = np.fmax.reduceat(y, starts, axis=0)
    values = np.empty((2 * buckets, y.shape[1]))
    values[0::2], values[1::2] = low, high
    return np.repeat(t[starts], 2), values


_Row = tuple[str, str, np.ndarray, np.ndarray, tuple[str, ...]]


def _rows_from_report(report: BagReport) -> list[_Row]:
    """(title, y label, stamps [ns], values (N, n), joint names) per quantity, contract first."""
    contract = report.contract
    labels = {
        (contract.joint_states, 'position'): ('joint position', 'position [rad]'),
        (contract.joint_states, 'velocity'): ('joint velocity', 'velocity [rad/s]'),
        (contract.motor_currents, 'effort'): ('motor current', 'current [A]'),
        (contract.joint_states, 'effort'): ('joint torque', 'torque [N*m]'),
    }
    units = {'position': '[rad or m]', 'velocity': '[rad/s or m/s]', 'effort': '[N*m or N]'}
    rows: list[_Row] = []
    keys = list(labels) + [
        (topic, key) for topic in report.series for key in FIELDS if (topic, key) not in labels
    ]
    for topic, key in keys:
        series = report.series.get(topic)
        values = None if series is None else getattr(series, key)
        if series is None or values is None or not len(values):
            continue
        title, ylabel = labels.get((topic, key), (key, f'{key} {units[key]}'))
        rows.append((f'{title} ({topic})', ylabel, series.stamps_ns, values, series.names))
    return rows


def _rows_from_recording(recording: Recording) -> list[_Row]:
    quantities = (
        ('joint position', 'position [rad]', recording.position),
        ('joint velocity', 'velocity [rad/s]', recording.velocity),
        ('motor current', 'current [A]', recording.current),
        ('joint torque', 'torque [N*m]', recording.joint_torque),
    )
    return [
        (title, ylabel, recording.stamps_ns, values, recording.joints)
        for title, ylabel, values in quantities
        if values is not None
    ]


def plot_report(
    report: BagReport,
    out_png: Path | str,
    *,
    recording: Recording | None = None,
    max_points: int = 5000,
) -> Path:
    """Plot each joint's position, velocity, motor current and torque over time to one PNG.

    One row per quantity, one line per joint. Lines are decimated to at most ``max_points``
    points (per-bucket minimum and maximum, so spikes stay visible). Uses matplotlib's Agg canvas
    directly: no GUI, no change to pyplot's global state.

    Args:
        report: from ``inspect_bag``; its JointState samples are plotted unless a recording is
            given.
        out_png: the image to write; parent folders are created.
        recording: plot these samples instead (e.g. a loaded and filtered recording).
        max_points: upper bound on points per line.

    Returns:
        out_png.

    Raises:
        ConfigError: max_points is below 2.
    """
    from matplotlib.figure import Figure

    if max_points < 2:
        raise ConfigError(f'max_points must be at least 2, got {max_points}')
    out_png = Path(out_png)
    rows = _rows_from_recording(recording) if recording is not None else _rows_from_report(report)
    firsts = [int(stamps[0]) for _, _, stamps, _, _ in rows if len(stamps)]
    origin = min(firsts) if firsts else report.start_ns

    figure = Figure(figsize=(12, 2.8 * max(len(rows), 1)), layout='constrained')
    axes = figure.subplots(max(len(rows), 1), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (title, ylabel, stamps, values, joints) in zip(axes, rows, strict=False):
        t, y = _envelope((stamps - origin) * 1e-9, values, max_points)
        for column, joint in enumerate(joints):
            ax.plot(t, y[:, column], linewidth=0.8, label=joint)
        ax.set_title(title, loc='left', fontsize='medium')
        ax.set_ylabel(ylabel)
        ax.grid(visible=True, alpha=0.3)
        ax.legend(loc='upper left', bbox_to_anchor=(1.005, 1.0), fontsize='small', frameon=False)
    if not rows:
        axes[0].text(0.5, 0.5, 'no JointState samples', ha='center', va='center')
    axes[-1].set_xlabel('time since first sample [s]')
    robot = f', robot {report.robot_name}' if report.robot_name else ''
    figure.suptitle(f'{report.path}: {report.start_iso}, {report.duration_s:.1f} s{robot}')
    out_png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out_png, dpi=100, format='png')
    return out_png
