"""Inspect a bag without judging it: timing, gaps, value ranges, limits and contract, as a report.

Unlike ``load_recording``, nothing here rejects a bag for its contents: NaN values, gaps, repeated
or backward stamps, joint-name changes and mismatched contract topics are counted and reported.
Only a bag that cannot be read at all raises ``BagError``.

This module reads the bag and computes the report. The report types live in ``inspect_report.py``
(``BagReport`` and the others stay importable from here), the text form in ``inspect_text.py``
and the plot in ``inspect_plot.py`` (both re-exported here).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from rosbags.serde import SerdeError

from id_learning.bag import (
    JOINT_STATE,
    JointStateSeries,
    bag_info,
    decode_joint_state,
    iter_typed,
)
from id_learning.bag.messages import clock_step
from id_learning.dataset.content import (
    GravityTorque,
    label_findings,
    motion_findings,
    sampling_problem,
)
from id_learning.dataset.inspect_checks import (
    consistency_failures,
    iso_utc,
    joint_accelerations,
    log_time_problems,
    metadata_mismatches,
    velocity_scale_problem,
)
from id_learning.dataset.inspect_nominal import with_nominal_lines
from id_learning.dataset.inspect_plot import plot_report
from id_learning.dataset.inspect_report import (
    FIELDS,
    GAP_PERIODS,
    MAX_LISTED,
    BagReport,
    ContractReport,
    FieldStats,
    Gap,
    JointReport,
    TimingReport,
    TopicReport,
)
from id_learning.dataset.inspect_text import render_report
from id_learning.dataset.plausibility import effort_bound, first_unpaired
from id_learning.errors import ConfigError
from id_learning.robot.config import RobotConfig, TopicConfig
from id_learning.robot.drives import amperes_per_newton_metre

__all__ = ['inspect_bag', 'plot_report', 'render_report']

_LOG = logging.getLogger(__name__)

NS_PER_S = 1_000_000_000


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


def _joint_reports(
    series: JointStateSeries,
    robot: RobotConfig | None,
    effort: str | None = None,
    motion: bool = False,
) -> tuple[JointReport, ...]:
    """Per joint: statistics and, with a robot, the shares beyond its limits.

    ``effort``: what the topic's effort is, 'current' or 'torque' (checked against the torque
    limits as ``load_recording`` checks it), or None (not checked). ``motion``: the topic is
    the joint states, whose accelerations are judged as ``load_recording`` judges them.
    """
    accelerations = joint_accelerations(series, robot) if motion else {}
    reports = []
    for column, name in enumerate(series.names):
        stats: dict[str, FieldStats | None] = {}
        for key in FIELDS:
            array = getattr(series, key)
            stats[key] = None if array is None else _field_stats(array[:, column])
        position_out = velocity_out = effort_out = effort_peak = None
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
            if effort is not None and series.effort is not None and len(series.effort):
                effort_out, effort_peak = _beyond_drive(
                    series.effort[:, column], robot, joint, effort
                )
        reports.append(
            JointReport(
                name=name,
                position=stats['position'],
                velocity=stats['velocity'],
                effort=stats['effort'],
                position_outside_limits=position_out,
                velocity_outside_limits=velocity_out,
                effort_outside_limits=effort_out,
                effort_peak_ratio=effort_peak,
                effort_kind=None if effort_out is None else effort,
                acceleration_beyond=accelerations.get(name),
            )
        )
    return tuple(reports)


def _beyond_drive(
    values: np.ndarray, robot: RobotConfig, joint: int, effort: str
) -> tuple[float, float | None]:
    """(share beyond, largest |value| / bound) of one joint's efforts against its drive.

    The bound is ``load_recording``'s (``plausibility.effort_bound``): currents times gear ratio
    and torque constant, or joint torques, within ``TORQUE_FACTOR`` x the torque limit.
    """
    drives = robot.drives
    per_nm = None
    if effort == 'current':
        per_nm = amperes_per_newton_metre(drives)[joint : joint + 1]
    bound = float(effort_bound(robot.limits.torque[joint : joint + 1], per_nm)[0])
    finite = np.abs(values[np.isfinite(values)])
    if not finite.size:
        return 0.0, None
    return float(np.mean(finite > bound)), float(finite.max() / bound)


def _content(
    series: JointStateSeries, label: str | None, motion: bool, robot: RobotConfig | None
) -> tuple[str, ...]:
    """``dataset.content``'s findings on a contract topic, one line each.

    ``label``: what the effort is ('motor current', 'joint torque') when it is the label, else
    None; ``motion``: judge the positions. With a robot only its joints are judged (a gripper's
    finger may stand still). Refusals say so.
    """
    stamps = series.stamps_ns
    duration = float(stamps.max() - stamps.min()) * 1e-9 if stamps.size > 1 else None
    columns = [k for k, name in enumerate(series.names) if robot is None or name in robot.joints]
    names = [series.names[k] for k in columns]
    findings = []
    if motion and series.position is not None and len(series.position) > 1 and names:
        findings += motion_findings(series.position[:, columns], names, duration_s=duration)
    if label is not None and series.effort is not None and len(series.effort) and names:
        unit = 'A' if label == 'motor current' else 'N*m'
        findings += label_findings(
            series.effort[:, columns], names, quantity=label, unit=unit, duration_s=duration
        )
    return tuple(
        finding.text + ('; train and diagnose refuse the bag' if finding.refuses else '')
        for finding in findings
    )


def _sampling(
    name: str, stamps: list[int], topics: TopicConfig, robot: RobotConfig | None
) -> str | None:
    """A contract topic's stamps against the robot's IPO period (``content.sampling_problem``)."""
    if robot is None or name not in (topics.joint_states, topics.motor_currents):
        return None
    return sampling_problem(np.array(stamps, dtype=np.int64), robot.ipo_period_s, name)


@dataclass
class _JointStateTopic:
    """Accumulates the decoded messages of one JointState topic."""

    topic: str
    names: tuple[str, ...] | None = None
    lengths: dict[str, int] = field(default_factory=dict)
    all_stamps: list[int] = field(default_factory=list)
    all_index: list[int] = field(default_factory=list)
    all_logs: list[int] = field(default_factory=list)
    clock_step: str | None = None
    stamps: list[int] = field(default_factory=list)
    logs: list[int] = field(default_factory=list)
    rows: dict[str, list[np.ndarray]] = field(default_factory=lambda: {key: [] for key in FIELDS})
    undecodable: int = 0
    inconsistent: int = 0
    first_inconsistent: int | None = None
    invalid_stamps: int = 0
    first_invalid_stamp: str | None = None

    def add(self, index: int, log_ns: int, data: bytes) -> None:
        try:
            msg = decode_joint_state(data)
        except (SerdeError, ValueError, IndexError, KeyError, struct.error):
            # Damaged bytes are a finding here, not an error: count them and go on.
            self.undecodable += 1
            return
        if msg.stamp_problem is not None:  # reported; the sample stays, stamped as stored
            self.invalid_stamps += 1
            if self.first_invalid_stamp is None:
                self.first_invalid_stamp = f'sample {index}: {msg.stamp_problem}'
        self.all_stamps.append(msg.stamp_ns)
        self.all_index.append(index)
        self.all_logs.append(log_ns)
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

    def to_header_order(self) -> None:
        """Put the samples in header-stamp order where the recorder's clock stepped back.

        The finding (``bag.clock_step``) goes to ``clock_step``; the samples are then numbered
        in header-stamp order, as train numbers them. Else they stay in log-time order.
        """
        step = clock_step(
            np.array(self.all_stamps, dtype=np.int64), np.array(self.all_logs, dtype=np.int64)
        )
        if step is None:
            return
        self.all_stamps = [self.all_stamps[k] for k in step.order]
        self.all_logs = [self.all_logs[k] for k in step.order]
        self.all_index = list(range(len(self.all_stamps)))
        kept = np.argsort(np.array(self.stamps, dtype=np.int64), kind='stable')
        self.stamps = [self.stamps[k] for k in kept]
        self.logs = [self.logs[k] for k in kept]
        self.rows = {
            key: [rows[k] for k in kept] if rows else rows for key, rows in self.rows.items()
        }
        span_s = (self.all_stamps[-1] - self.all_stamps[0]) * 1e-9
        self.clock_step = (
            f'{step.describe(self.topic)}; timed here in header-stamp order, as train reads it: '
            f'the header stamps span {span_s:.3f} s (start and duration above are log times)'
        )

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


def _effort_kind(
    name: str, topics: TopicConfig, decoded: Mapping[str, _JointStateTopic]
) -> tuple[str | None, str | None]:
    """What a topic's effort is ('current', 'torque' or None) and its label's name, if a label.

    The motor currents' effort is the label; the joint states' effort (joint torques) is one
    only when the bag has no motor currents (a recording for ``--target joint``).
    """
    if name == topics.motor_currents:
        return 'current', 'motor current'
    if name == topics.joint_states:
        return 'torque', None if topics.motor_currents in decoded else 'joint torque'
    return None, None


def _contract(
    topics: TopicConfig,
    msgtypes: Mapping[str, str],
    decoded: Mapping[str, _JointStateTopic],
    several_types: tuple[str, ...],
    period_s: float | None,
) -> ContractReport:
    """The contract's topics, and whether they pair (``period_s``: None for their median step)."""
    names = (topics.joint_states, topics.motor_currents)
    needed = {topics.joint_states: ('position', 'velocity'), topics.motor_currents: ('effort',)}
    empty = tuple(
        (name, key)
        for name in names
        if name in decoded and decoded[name].names is not None
        for key in needed[name]
        if not decoded[name].lengths.get(key)
    )
    mixed = tuple(name for name in names if name in several_types)
    missing = tuple(name for name in names if msgtypes.get(name) != JOINT_STATE)
    if missing:
        wrong = tuple((name, msgtypes[name]) for name in missing if name in msgtypes)
        states = decoded.get(topics.joint_states)
        torques_only = (
            missing == (topics.motor_currents,)
            and not wrong
            and states is not None
            and bool(states.all_stamps)
            and bool(states.lengths.get('effort'))
        )
        return ContractReport(*names, missing, None, None, None, wrong, torques_only, empty, mixed)
    states, currents = decoded[topics.joint_states], decoded[topics.motor_currents]
    a = np.array(states.all_stamps, dtype=np.int64)
    b = np.array(currents.all_stamps, dtype=np.int64)
    size = min(a.size, b.size)
    steps = np.diff(a)
    period = (
        period_s
        if period_s is not None
        else (float(np.median(steps)) * 1e-9 if steps.size else 0.0)
    )
    first = first_unpaired(a, b, period)
    if first is None and a.size != b.size:
        first = size
    names_match = (
        None if states.names is None or currents.names is None else states.names == currents.names
    )
    return ContractReport(
        *names, (), first is None, first, names_match, empty_fields=empty, several_types=mixed
    )


def _joint_state_report(
    decoded: Mapping[str, _JointStateTopic],
    name: str,
    *,
    count: int,
    nominal: float | None,
    topics: TopicConfig,
    robot: RobotConfig | None,
) -> tuple[TopicReport, JointStateSeries]:
    """One JointState topic's report (timing, joints against the robot, findings), its samples."""
    acc = decoded[name]
    timing = _timing(
        np.array(acc.all_stamps, dtype=np.int64),
        np.array(acc.all_index, dtype=np.int64),
        nominal,
        'header',
    )
    series = acc.series()
    contradictions, first = consistency_failures(series, robot)
    effort, label = _effort_kind(name, topics, decoded)
    motion = name == topics.joint_states
    report = TopicReport(
        name=name,
        msgtype=JOINT_STATE,
        count=count,
        timing=timing,
        joints=_joint_reports(series, robot, effort, motion=motion),
        undecodable=acc.undecodable,
        inconsistent=acc.inconsistent,
        first_inconsistent=acc.first_inconsistent,
        invalid_stamps=acc.invalid_stamps,
        first_invalid_stamp=acc.first_invalid_stamp,
        clock_step=acc.clock_step,
        contradictions=contradictions,
        first_contradiction=first,
        velocity_scale=None if contradictions else velocity_scale_problem(series, robot),
        content=_content(series, label, motion, robot),
        sampling=_sampling(name, acc.all_stamps, topics, robot),
    )
    return report, series


def inspect_bag(
    path: Path | str,
    robot: RobotConfig | None = None,
    period_s: float | None = None,
    gravity: GravityTorque | None = None,
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
        gravity: the robot's gravity torque at positions: with ``robot``, the label of each
            joint is judged against it (``content.gravity_findings``: sign and scale).

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
    types: dict[str, list[str]] = {}
    for topic_info in info.topics:
        types.setdefault(topic_info.name, []).append(topic_info.msgtype)
    # A topic of several types is reported by one: JointState where it is one of them.
    msgtypes = {
        name: JOINT_STATE if JOINT_STATE in kind else kind[0] for name, kind in types.items()
    }
    names = list(types)
    topics = robot.topics if robot else TopicConfig()
    decoded = {
        name: _JointStateTopic(name) for name, kind in msgtypes.items() if kind == JOINT_STATE
    }
    every: dict[tuple[str, str], list[int]] = {(t.name, t.msgtype): [] for t in info.topics}
    log_times = {name: every[name, msgtype] for name, msgtype in msgtypes.items()}
    for topic, msgtype, log_ns, data in iter_typed(path, names):
        every[topic, msgtype].append(log_ns)
        if topic in decoded and msgtype == JOINT_STATE:
            decoded[topic].add(len(log_times[topic]) - 1, log_ns, data)
    for accumulated in decoded.values():
        accumulated.to_header_order()
    several_types = tuple(
        (name, tuple((kind, len(every[name, kind])) for kind in dict.fromkeys(kinds)))
        for name, kinds in types.items()
        if len(set(kinds)) > 1
    )

    reports = []
    series: dict[str, JointStateSeries] = {}
    for name in names:
        count = len(log_times[name])
        if name in decoded:
            topic_report, series[name] = _joint_state_report(
                decoded, name, count=count, nominal=nominal, topics=topics, robot=robot
            )
            reports.append(topic_report)
        else:
            stamps = np.array(log_times[name], dtype=np.int64)
            timing = _timing(stamps, np.arange(count), None, 'log')
            reports.append(TopicReport(name, msgtypes[name], count, timing))

    reports = with_nominal_lines(reports, series, topics, robot, gravity)
    # The messages' own span, not metadata.yaml's (which may be edited or copied): a
    # disagreement is named among the problems (``metadata_mismatches``).
    firsts = [min(times) for times in every.values() if times]
    start_ns = min(firsts) if firsts else info.start_ns
    end_ns = max((max(times) for times in every.values() if times), default=start_ns)
    order = (f'metadata: {info.order_note.removeprefix(f"{path}: ")}',) if info.order_note else ()
    report = BagReport(
        metadata_mismatches=order
        + metadata_mismatches(path, info.topics, every)
        + log_time_problems(every),
        several_types=several_types,
        path=path,
        storage=info.storage,
        files=info.files,
        start_ns=start_ns,
        start_iso=iso_utc(start_ns),
        duration_s=(end_ns - start_ns if firsts else info.duration_ns) * 1e-9,
        message_count=sum(len(times) for times in every.values()),
        robot_name=robot.name if robot else None,
        topics=tuple(reports),
        contract=_contract(
            topics,
            msgtypes,
            decoded,
            tuple(name for name, _ in several_types),
            nominal,
        ),
        series=series,
        robot_joints=robot.joints if robot else (),
    )
    _LOG.debug('%s: %d messages on %d topics inspected', path, report.message_count, len(names))
    return report
