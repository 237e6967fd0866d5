"""Checks ``inspect_bag`` runs over what it read, each finding one line or one count.

Kept apart from the reading (``inspect.py``): whether a joint-state topic describes one motion
(the consistency gate) and one a controller can send (the acceleration gate), and whether
metadata.yaml and the log times describe the messages the files hold.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from id_learning.bag import JointStateSeries, TopicInfo
from id_learning.bag.metadata_file import metadata_text
from id_learning.config_io import parse_yaml
from id_learning.dataset.accelerations import (
    AccelerationExcess,
    acceleration_excess,
    controller_accelerations,
)
from id_learning.dataset.consistency import KinematicConsistency, gap_starts
from id_learning.dataset.inspect_report import GAP_PERIODS
from id_learning.errors import BagError, ConfigError
from id_learning.robot.config import RobotConfig

__all__ = [
    'consistency_failures',
    'iso_utc',
    'joint_accelerations',
    'log_time_problems',
    'metadata_mismatches',
    'velocity_scale_problem',
]

NS_PER_S = 1_000_000_000
#: How far metadata.yaml's starting_time may lie from the first message's log time [ns].
START_TOLERANCE_NS = NS_PER_S


def joint_accelerations(
    series: JointStateSeries, robot: RobotConfig | None
) -> dict[str, AccelerationExcess]:
    """By joint, the controller accelerations beyond the predictor's gate (with a robot).

    Only where the topic names exactly the robot's joints with positions and velocities.
    """
    q, v = series.position, series.velocity
    if robot is None or q is None or v is None or len(q) < 2:
        return {}
    if sorted(series.names) != sorted(robot.joints):
        return {}
    order = [series.names.index(name) for name in robot.joints]
    a = controller_accelerations(robot, series.stamps_ns, q[:, order], v[:, order])
    excess = acceleration_excess(robot, series.stamps_ns, a)
    return {name: e for name, e in zip(robot.joints, excess, strict=True) if e is not None}


@dataclass(frozen=True)
class _GateInput:
    """A topic's samples as the consistency gate reads them, in the robot's joint order."""

    gate: KinematicConsistency
    stamps: np.ndarray
    q: np.ndarray
    v: np.ndarray
    bad: np.ndarray
    starts: tuple[int, ...]


def _gate_input(series: JointStateSeries, robot: RobotConfig | None) -> _GateInput | None:
    """Only where the topic names exactly the robot's joints with positions and velocities.

    Rows with a non-finite value (zeroed, ``bad``), and stamps that do not increase, start a
    new segment (they are reported on their own).
    """
    q, v = series.position, series.velocity
    if robot is None or q is None or v is None or set(series.names) != set(robot.joints):
        return None
    if len(series.names) != len(robot.joints) or len(q) < 2:
        return None
    order = [series.names.index(name) for name in robot.joints]
    stamps = np.asarray(series.stamps_ns, dtype=np.int64)
    q, v = q[:, order], v[:, order]
    bad = ~(np.isfinite(q).all(axis=1) & np.isfinite(v).all(axis=1))
    bad[1:] |= np.diff(stamps) <= 0
    breaks = np.flatnonzero(bad)  # a bad row is a segment of its own
    gaps = gap_starts(stamps, robot.ipo_period_s, GAP_PERIODS)
    starts = tuple(sorted({*gaps, *breaks.tolist(), *(breaks + 1).tolist()} - {len(stamps)}))
    clean_q, clean_v = np.where(bad[:, None], 0.0, q), np.where(bad[:, None], 0.0, v)
    gate = KinematicConsistency.for_robot(robot)
    return _GateInput(gate, stamps, clean_q, clean_v, bad, starts)


def consistency_failures(
    series: JointStateSeries, robot: RobotConfig | None
) -> tuple[int, str | None]:
    """(samples failing the consistency gate, the first described) of the robot's joints."""
    given = _gate_input(series, robot)
    if given is None:
        return 0, None
    gate, stamps, clean_q, clean_v, starts = (
        given.gate,
        given.stamps,
        given.q,
        given.v,
        given.starts,
    )
    failing = gate.failing(stamps, clean_q, clean_v, starts=starts) & ~given.bad
    if not failing.any():
        return 0, None
    k = int(np.argmax(failing))
    begin = max(start for start in starts if start <= k)  # explained within its segment
    part = slice(begin, None)
    worst = gate.explain(k - begin, stamps[part], clean_q[part], clean_v[part], None)
    text = f'sample {k} (stamp {int(stamps[k])} ns): {worst.describe()}'
    if gate.scale < 1.0 and not (
        KinematicConsistency(gate.joints, gate.limits, gate.period_s)
        .failing(stamps, clean_q, clean_v, starts=starts)
        .any()
    ):
        text += (
            f"; only the robot config's consistency_scale {gate.scale:g} makes them fail (every "
            f'tolerance {1 / gate.scale:.4g} x tighter): at 1 none does'
        )
    return int(failing.sum()), text


def velocity_scale_problem(series: JointStateSeries, robot: RobotConfig | None) -> str | None:
    """Joints whose velocities are a multiple of their positions' rate over the whole recording.

    The loader's whole-recording check (``KinematicConsistency.scale_errors``): a factor such
    as deg/s for rad/s, 2, or a reversed sign passes the sample-to-sample gate when the motion
    is slow. None when every joint agrees, or the topic is not judged (``_gate_input``).
    """
    given = _gate_input(series, robot)
    if given is None:
        return None
    errors = given.gate.scale_errors(given.stamps, given.q, given.v, starts=given.starts)
    return given.gate.describe_scale(errors) if errors else None


def iso_utc(stamp_ns: int) -> str:
    """A stamp [ns since epoch] in ISO 8601, UTC, to the microsecond."""
    seconds, rest = divmod(stamp_ns, NS_PER_S)
    moment = datetime.fromtimestamp(seconds, UTC).replace(microsecond=rest // 1000)
    return moment.isoformat(timespec='microseconds').replace('+00:00', 'Z')


def metadata_mismatches(
    path: Path, topics: tuple[TopicInfo, ...], log_times: Mapping[tuple[str, str], list[int]]
) -> tuple[str, ...]:
    """Where metadata.yaml contradicts the messages the data files hold, one line each.

    A metadata.yaml written by hand or copied from another recording: its message_count, a
    topic's message_count or its duration disagree with what was read (a negative duration
    never fits), or its starting_time lies more than ``START_TOLERANCE_NS`` from the first
    message's log time. ``log_times`` holds the messages read by (topic, type).
    """
    counts: dict[tuple[str, str], int] = {}
    for topic in topics:
        key = (topic.name, topic.msgtype)
        counts[key] = counts.get(key, 0) + topic.count
    several = {name for name, _ in counts if sum(name == other for other, _ in counts) > 1}
    lines = [
        f'metadata: {name}{f" ({msgtype})" if name in several else ""} message_count {count}, '
        f'the file holds {len(log_times[name, msgtype])}'
        for (name, msgtype), count in counts.items()
        if count != len(log_times[name, msgtype])
    ]
    try:
        document = parse_yaml(metadata_text(path), str(path))
        meta = document['rosbag2_bagfile_information']
    except (BagError, ConfigError, KeyError, TypeError):
        return tuple(lines)  # the reader opened the bag: what it read is checked above
    held = sum(len(times) for times in log_times.values())
    count = meta.get('message_count') if isinstance(meta, dict) else None
    if count is not None and count != held:
        lines.append(f'metadata: message_count {count}, the files hold {held}')
    duration = meta.get('duration', {}) if isinstance(meta, dict) else {}
    stated = duration.get('nanoseconds') if isinstance(duration, dict) else None
    stamps = [t for times in log_times.values() for t in times]
    span = max(stamps) - min(stamps) if stamps else 0
    if stated is not None and stated != span:
        lines.append(
            f'metadata: duration {stated} ns, the messages span {span} ns (last minus first)'
        )
    starting = meta.get('starting_time', {}) if isinstance(meta, dict) else {}
    start = starting.get('nanoseconds_since_epoch') if isinstance(starting, dict) else None
    if stamps and isinstance(start, int) and abs(start - min(stamps)) > START_TOLERANCE_NS:
        lines.append(
            f'metadata: starting_time {start} ns ({_iso_or_ns(start)}), the first message is '
            f'logged at {min(stamps)} ns ({iso_utc(min(stamps))}); start and duration above '
            "are the messages'"
        )
    return tuple(lines)


def _iso_or_ns(stamp_ns: int) -> str:
    """``iso_utc``, or 'no date' where the stamp lies beyond the calendar's range."""
    try:
        return iso_utc(stamp_ns)
    except (OverflowError, OSError, ValueError):
        return 'no date'


def log_time_problems(every: Mapping[tuple[str, str], list[int]]) -> tuple[str, ...]:
    """A line when the log times of several messages do not advance at all.

    A recorder under ``use_sim_time`` with no /clock stamps every message with ROS time 0: the
    header stamps are fine, but the log times say nothing of when anything arrived.
    """
    times = [t for logs in every.values() for t in logs]
    if len(times) < 2 or min(times) != max(times):
        return ()
    return (
        f'log times: all {len(times)} messages carry the same log time {times[0]} ns '
        f"({iso_utc(times[0])}): the recorder's clock stood still (use_sim_time without a /clock "
        'publisher?); start and duration above are meaningless and a `timing: log_time` replay '
        'would send every message at once (the header stamps, which train reads, are not '
        'affected): record again with a running clock',
    )
