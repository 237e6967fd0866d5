"""The replay's plan: the played span of a bag as cycles, each the messages of one key.

``build_plan`` cuts the span in play order, reads it (with ``REFERENCE_PAD_S`` around it for the
reference), checks it (``replay_span``), builds the reference from the ``reference_source`` joint
states and groups everything into cycles by key: the header stamp (``timing: stamp``) or the log
time (``timing: log_time``). ``replay.py`` plays the cycles on their deadlines.

Play order is the bag's (log-time) order, except for a topic whose log times step back while its
header stamps advance (``bag.messages.clock_step``: the recorder's clock stepped back): with
``timing: stamp`` it is played in header-stamp order, as train and inspect read it, with one
warning naming the step. The whole bag's stamps decide it (read cheaply, ``_stamp_reader``), and
the span is cut by key, never by log time: the stepped part, logged early, is not skipped. Any
other disorder of the stamps (a sender's) is refused by ``replay_span``, as before.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Container, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.bag import JOINT_STATE, bag_info, decode_joint_state, iter_raw
from id_learning.bag.messages import ClockStep, clock_step, typestore
from id_learning.dataset.consistency import KinematicConsistency, gap_starts
from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.plausibility import check_accelerations, check_motion
from id_learning.errors import BagError, ConfigError, DatasetError
from id_learning.nodes.msg_conversions import (
    joint_state_message,
    serialize_exact,
    trajectory_message,
)
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay_span import (
    check_timing,
    check_topics_play,
    header_stamp_ns,
    source_stretch,
    stamp_notes,
)
from id_learning.predictor.guards import stamp_problem
from id_learning.predictor.reference import reference_from_states
from id_learning.robot.config import RobotConfig

__all__ = ['REFERENCE_PAD_S', 'Cycle', 'ReplayPlan', 'build_plan', 'check_smoothing', 'span_keys']

NS_PER_S = 1_000_000_000
#: Joint states read beyond each end of the span for the reference's zero-phase filter [s].
REFERENCE_PAD_S = 10.0


@dataclass
class Cycle:
    """What is published at one deadline.

    Attributes:
        offset_ns: time after the first cycle at rate 1 [ns].
        stamp_ns: the cycle's stamp, published on /clock [ns].
        messages: (topic index, serialized bytes) in bag order, then the reference (index -1).
    """

    offset_ns: int
    stamp_ns: int
    messages: list[tuple[int, bytes]] = field(default_factory=list)


@dataclass
class ReplayPlan:
    """The cycles of the replayed span and the topics they publish on."""

    topics: tuple[str, ...]
    msg_types: tuple[str, ...]
    cycles: list[Cycle]
    period_ns: int
    #: What the node logs as warnings before playing (an unpaired tail).
    warnings: tuple[str, ...] = ()

    @property
    def duration_ns(self) -> int:
        """From the first to the last cycle at rate 1 [ns]."""
        return self.cycles[-1].offset_ns if self.cycles else 0

    @property
    def message_count(self) -> int:
        """Messages of the bag's topics (without /clock and the reference)."""
        return sum(1 for cycle in self.cycles for index, _ in cycle.messages if index >= 0)


def _reference_bytes(
    config: ReplayConfig, robot: RobotConfig, states: list[bytes], keep: list[bool]
) -> list[bytes | None]:
    """Serialized reference messages built from the source topic's joint states, in order.

    The reference is computed over all ``states`` (the span plus padding, so that the zero-phase
    filter's edge transients fall outside the span) and serialized where ``keep`` is set.
    """
    decoded = []
    for k, data in enumerate(states):
        try:
            decoded.append(decode_joint_state(data))
        except Exception as err:  # foreign bytes: SerdeError and others
            raise BagError(
                f'{config.bag}: {config.reference_source} message {k} of the replayed span is '
                f'not a valid JointState ({type(err).__name__}: {err})'
            ) from err
    if len(decoded) < 3:
        raise BagError(
            f'{config.bag}: {config.reference_source} has {len(decoded)} messages in the '
            'replayed span; a reference needs at least 3'
        )
    names = decoded[0].name
    if any(msg.name != names for msg in decoded):
        raise BagError(f'{config.bag}: joint names change within {config.reference_source}')
    stamps = np.array([msg.stamp_ns for msg in decoded], dtype=np.int64)
    q = np.vstack([msg.position for msg in decoded])
    v = np.vstack([msg.velocity for msg in decoded])
    limits = None
    if set(names) == set(robot.joints) and len(names) == len(robot.joints):
        limits = robot.limits.take([robot.joints.index(name) for name in names])
    try:
        where = f'{config.bag}: {config.reference_source}'
        check_motion(tuple(names), stamps, q, v, limits=limits, where=where)
    except DatasetError as err:
        raise BagError(f'{err}; nothing is played from an impossible reference') from err
    inputs = None
    if config.reference_inputs != 'recorded':  # the robot's cut-offs, in the bag's joint order
        order = [robot.joints.index(name) for name in names]
        if config.reference_inputs == 'study':
            inputs = InputDefinition.study(robot.lowpass_cutoff_hz[order])
        elif config.reference_smoothing_hz > 0:
            inputs = InputDefinition.controller(np.full(len(names), config.reference_smoothing_hz))
        else:
            inputs = InputDefinition.controller(robot.input_smoothing_hz[order])
    try:
        reference = reference_from_states(
            names, stamps, q, v, period_s=robot.ipo_period_s, inputs=inputs
        )
    except DatasetError as err:
        raise BagError(f'{config.bag}: {config.reference_source}: {err}') from err
    if limits is not None:  # the accelerations the predictor will be sent, bounded as it does
        try:
            check_accelerations(
                tuple(names), reference.stamps_ns, reference.a, limits=limits, where=where
            )
            # Recorded positions and velocities must describe one motion (the predictor's gate).
            KinematicConsistency.for_robot(robot, tuple(names)).check(
                stamps, q, v, where=where, starts=gap_starts(stamps, robot.ipo_period_s, 3.0)
            )
        except DatasetError as err:
            raise BagError(f'{err}; nothing is played from an impossible reference') from err
    out: list[bytes | None] = []
    for k, stamp in enumerate(reference.stamps_ns.tolist()):
        if not keep[k]:
            out.append(None)
            continue
        if config.reference_mode == 'trajectory':
            msg: Any = trajectory_message(
                stamp, names, reference.q[k], reference.v[k], reference.a[k]
            )
        else:
            msg = joint_state_message(
                stamp, names, position=reference.q[k], velocity=reference.v[k]
            )
        out.append(serialize_exact(msg))
    return out


def _check_joint_names(config: ReplayConfig, robot: RobotConfig, data: bytes) -> None:
    """Refuse a reference of other joints than the robot's, before the timing (as train does)."""
    try:  # foreign bytes are refused, with the message's number, in _reference_bytes
        names = decode_joint_state(data).name
    except Exception:
        names = robot.joints
    if config.reference_inputs != 'recorded' and sorted(names) != sorted(robot.joints):
        raise BagError(
            f'{config.bag}: {config.reference_source} joints {list(names)} are not the robot '
            f'{robot.name} joints {list(robot.joints)}; set robot_config to the robot of the '
            'bag, or reference_inputs recorded'
        )


def check_smoothing(config: ReplayConfig, robot: RobotConfig) -> None:
    """Refuse a reference_smoothing_hz the robot config would refuse as input_smoothing_hz.

    It must lie above the label cut-offs (the reference keeps the motion the labels smear:
    models are fitted and scored on such inputs) and below the Nyquist frequency of the IPO.
    """
    hz, nyquist = config.reference_smoothing_hz, 0.5 / robot.ipo_period_s
    if config.reference_mode == 'none' or config.reference_inputs != 'controller' or hz == 0:
        return
    cutoffs = robot.lowpass_cutoff_hz.tolist()
    if not max(cutoffs) < hz < nyquist:
        raise ConfigError(
            f'node replay: reference_smoothing_hz {hz:g} Hz must lie above the label cut-offs '
            f'lowpass_cutoff_hz {cutoffs} of robot config {robot.source or robot.name} (the '
            'reference keeps the motion the labels smear, as input_smoothing_hz does) and below '
            f"the Nyquist frequency {nyquist:g} Hz of the IPO period; 0: the robot config's "
            f'input_smoothing_hz {robot.input_smoothing_hz.tolist()}'
        )


#: A message whose first field is a std_msgs/Header starts, after the CDR encapsulation header
#: (byte 1: 1 little-endian, 0 big-endian), with the stamp: int32 sec, uint32 nanosec.
_CDR_HEADER = 4
_LITTLE_TIME = struct.Struct('<iI')
_BIG_TIME = struct.Struct('>iI')


def _stamp_reader(path: Path, topic: str, msgtype: str) -> Callable[[bytes, int], int]:
    """How to read the header stamps of a topic: (bytes, message number) -> stamp [ns].

    Every stamp of the topics read by their stamps is read, to find a clock step (the whole
    topic decides it, as train reads it): of a message that starts with its header, the stamp
    is taken from its first bytes, a tenth of the cost of decoding it. Any other message, and a
    stamp that is no time there, is decoded, so that ``header_stamp_ns`` names what is wrong.

    Raises:
        BagError: (when called) the message is no message of its type, its stamp is invalid,
            or its type has no header.
    """
    store = typestore()
    fields = dict(store.get_msgdef(msgtype).fields) if msgtype in store.types else {}
    leads = next(iter(fields), None) == 'header' and fields['header'][1] == 'std_msgs/msg/Header'

    def stamp_ns(data: bytes, number: int) -> int:
        if leads and len(data) >= _CDR_HEADER + _LITTLE_TIME.size and data[0] == 0:
            time_layout = _LITTLE_TIME if data[1] else _BIG_TIME
            sec, nanosec = time_layout.unpack_from(data, _CDR_HEADER)
            if stamp_problem(sec, nanosec) is None:
                return int(sec) * NS_PER_S + int(nanosec)
        stamp = header_stamp_ns(data, msgtype, f'{path}: {topic} message {number}')
        if stamp is None:
            raise BagError(
                f'{path}: {topic} ({msgtype}) has no header stamp; use timing:=log_time'
            )
        return stamp

    return stamp_ns


@dataclass(frozen=True)
class _PlayOrder:
    """One topic's messages in the order they are played, with what the plan needs of them.

    Attributes:
        keys: (N,) each message's key: its header stamp, or its log time [ns].
        stamps: (N,) header stamps [ns], or None where the topic's stamps are not read.
        numbers: (N,) each message's number in the topic as the bag holds it (log-time order).
        positions: (N,) each message's position among all messages read, in log-time order.
    """

    keys: np.ndarray
    stamps: np.ndarray | None
    numbers: np.ndarray
    positions: np.ndarray


def _play_orders(
    path: Path,
    needed: Sequence[str],
    readers: Mapping[str, Callable[[bytes, int], int]],
    *,
    by_stamp: bool,
) -> tuple[dict[str, _PlayOrder], str | None]:
    """Every message of the ``needed`` topics in play order, and the warning of a clock step.

    A bag comes in log-time order. By stamps (``by_stamp``), a topic whose log times step back
    where its header stamps advance (``bag.messages.clock_step``: the recorder's clock stepped
    back) is played in header-stamp order, as train reads it; one warning names the step. Any
    other order of the stamps is left to ``check_timing`` to refuse.
    """
    logs: dict[str, list[int]] = {topic: [] for topic in needed}
    stamps: dict[str, list[int]] = {topic: [] for topic in readers}
    positions: dict[str, list[int]] = {topic: [] for topic in needed}
    for position, (topic, log_ns, data) in enumerate(iter_raw(path, needed)):
        if topic in readers:
            stamps[topic].append(readers[topic](data, len(logs[topic])))
        logs[topic].append(log_ns)
        positions[topic].append(position)
    orders: dict[str, _PlayOrder] = {}
    steps: dict[str, ClockStep] = {}
    for topic in needed:
        log = np.array(logs[topic], dtype=np.int64)
        stamp = np.array(stamps[topic], dtype=np.int64) if topic in readers else None
        order = np.arange(log.size)
        if by_stamp and stamp is not None and (step := clock_step(stamp, log)) is not None:
            steps[topic], order = step, step.order
        key = stamp if by_stamp and stamp is not None else log
        orders[topic] = _PlayOrder(
            key[order],
            None if stamp is None else stamp[order],
            order,
            np.array(positions[topic], dtype=np.int64)[order],
        )
    if not steps:
        return orders, None
    first, *others = steps
    also = f' (so are {", ".join(others)}, whose log times step back too)' if others else ''
    return orders, f'{path}: {steps[first].describe(first)}; played in header-stamp order{also}'


@dataclass(frozen=True)
class _Span:
    """The messages of the played span, in play order.

    Attributes:
        keyed: (key [ns], topic index, bytes, position in the bag) of the played topics' messages.
        states: (key [ns], bytes, header stamp [ns]) of the reference source's, span and padding.
        firsts: each topic's number (in play order) of its first message read ('' the source).
        origin: the key start_offset_s counts from: the first message's [ns].
        start: the span's first key [ns].
        stop: its last key [ns], None: to the end.
        warnings: what the node warns of before playing (a clock step).
    """

    keyed: list[tuple[int, int, bytes, int]]
    states: list[tuple[int, bytes, int]]
    firsts: dict[str, int]
    origin: int
    start: int
    stop: int | None
    warnings: tuple[str, ...]


def span_keys(
    offset_s: float, duration_s: float, origin: int, last: int
) -> tuple[int, int | None]:
    """The first and last key of the played span [ns] (None: to the end) of a bag's keys.

    Whatever the seconds (the parameters are bounded, but this does not rely on it): a start
    beyond the bag's last key is just past it (nothing to play), a stop at or beyond it is the
    end; no product overflows.

    Args:
        offset_s: ``start_offset_s`` [s], from ``origin``.
        duration_s: ``duration_s`` [s]; 0: to the end.
        origin: the bag's first key [ns]; last: its last [ns].
    """
    length = last - origin
    offset = _ns_at_most(offset_s, length + 1)
    if duration_s <= 0:
        return origin + offset, None
    stop = origin + offset + _ns_at_most(duration_s, length - offset)
    return origin + offset, None if stop >= last else stop


def _ns_at_most(seconds: float, most: int) -> int:
    """``seconds`` [ns], at most ``most`` (inf and NaN too)."""
    ns = seconds * NS_PER_S
    return round(ns) if ns < most else most


def _read_span(
    config: ReplayConfig, path: Path, needed: Sequence[str], types: Mapping[str, str]
) -> _Span:
    """Read the played span of the bag (with ``REFERENCE_PAD_S`` around it for the source).

    The keys of the whole bag are read first (its stamps cheaply, ``_stamp_reader``), so that
    the span is cut in play order (a clock step on the recorder puts late samples early in the
    bag); then only the span's messages are taken, decoded where their stamps are read.

    Raises:
        BagError: a message has no header stamp, an invalid one, or is no message of its type.
        ConfigError: the bag holds no message of the needed topics.
    """
    has_reference = config.reference_mode != 'none'
    source = config.reference_source if has_reference else None
    by_stamp = config.timing == 'stamp'
    readers = {
        topic: _stamp_reader(path, topic, types[topic])
        for topic in needed
        if by_stamp or topic == source  # the reference carries the source's stamps
    }
    orders, warning = _play_orders(path, needed, readers, by_stamp=by_stamp)
    heads = [int(order.keys[0]) for order in orders.values() if order.keys.size]
    if not heads:
        raise ConfigError(f'{path}: no messages on {list(needed)}')
    origin = min(heads)
    last = max(int(order.keys.max()) for order in orders.values() if order.keys.size)
    start, stop = span_keys(config.start_offset_s, config.duration_s, origin, last)
    pad = round(REFERENCE_PAD_S * NS_PER_S) if has_reference else 0

    def within(keys: np.ndarray, margin: int) -> np.ndarray:
        inside = keys >= start - margin
        return np.flatnonzero(inside if stop is None else inside & (keys <= stop + margin))

    index = {topic: k for k, topic in enumerate(config.topics)}
    picked = {topic: within(orders[topic].keys, 0) for topic in index}
    if source is not None:
        picked[''] = within(orders[source].keys, pad)
    wanted: dict[str, set[int]] = {}
    for topic, rows in picked.items():
        name = topic or str(source)
        wanted.setdefault(name, set()).update(orders[name].numbers[rows].tolist())
    data = _messages(path, wanted, types, readers)
    keyed: list[tuple[int, int, bytes, int]] = []
    for topic, k in index.items():
        order = orders[topic]
        keyed.extend(
            (
                int(order.keys[row]),
                k,
                data[topic][int(order.numbers[row])],
                int(order.positions[row]),
            )
            for row in picked[topic]
        )
    states: list[tuple[int, bytes, int]] = []
    if source is not None:
        order = orders[source]
        assert order.stamps is not None  # a source's stamps are always read
        states = [
            (int(order.keys[row]), data[source][int(order.numbers[row])], int(order.stamps[row]))
            for row in picked['']
        ]
    firsts = {topic: int(rows[0]) for topic, rows in picked.items() if rows.size}
    warnings = () if warning is None else (warning,)
    return _Span(keyed, states, firsts, origin, start, stop, warnings)


def _messages(
    path: Path,
    wanted: Mapping[str, set[int]],
    types: Mapping[str, str],
    stamped: Container[str],
) -> dict[str, dict[int, bytes]]:
    """The bytes of the ``wanted`` messages: per topic, their numbers in the bag's order.

    A message whose stamp the plan reads is decoded (a message of its type, a valid stamp).
    Reading stops after the last wanted message.

    Raises:
        BagError: names the message that is no message of its type (``header_stamp_ns``).
    """
    found: dict[str, dict[int, bytes]] = {topic: {} for topic in wanted}
    left = sum(map(len, wanted.values()))
    counts = dict.fromkeys(wanted, -1)
    topics = [topic for topic, numbers in wanted.items() if numbers]
    for topic, _, data in iter_raw(path, topics) if topics else ():
        counts[topic] += 1
        if counts[topic] not in wanted[topic]:
            continue
        if topic in stamped:
            header_stamp_ns(data, types[topic], f'{path}: {topic} message {counts[topic]}')
        found[topic][counts[topic]] = data
        left -= 1
        if not left:
            break  # nothing later belongs to the span
    return found


def build_plan(config: ReplayConfig, robot: RobotConfig) -> ReplayPlan:
    """Load the replayed span of a bag into cycles.

    Only the span (with ``REFERENCE_PAD_S`` around it for the reference) is read and kept.

    Raises:
        BagError: the bag is unreadable, lacks a topic, or a message has no header stamp with
            ``timing: stamp``; a topic yields no message in the span, or its type in
            metadata.yaml differs from the storage's; the reference's joints are not the robot's.
        ConfigError: the span is empty, or reference_smoothing_hz is refused (``check_smoothing``).
    """
    check_smoothing(config, robot)
    path = Path(config.bag)
    info = bag_info(path)
    has_reference = config.reference_mode != 'none'
    needed = list(dict.fromkeys(config.topics))
    if has_reference and config.reference_source not in needed:
        needed.append(config.reference_source)
    types = {name: info.topic(name).msgtype for name in needed}
    if has_reference and types[config.reference_source] != JOINT_STATE:
        raise BagError(
            f'{path}: reference_source {config.reference_source} has type '
            f'{types[config.reference_source]}, expected {JOINT_STATE}'
        )
    span = _read_span(config, path, needed, types)
    keyed, states, start, stop = span.keyed, span.states, span.start, span.stop
    played = [sum(1 for item in keyed if item[1] == k) for k in range(len(config.topics))]
    checked = [*config.topics, *([config.reference_source] if has_reference else [])]
    if keyed:  # an empty span altogether is refused below as nothing to play
        check_topics_play(
            path,
            checked,
            [*played, *([len(states)] if has_reference else [])],
            {topic.name: topic.count for topic in info.topics},
            f'start_offset_s {config.start_offset_s} s, duration_s {config.duration_s} s',
        )

    def inside(key: int) -> bool:
        return key >= start and (stop is None or key <= stop)

    if has_reference and states:  # the joints, then train's timing checks, in the bag's order
        _check_joint_names(config, robot, states[0][1])
        stretch = source_stretch(
            f'{path}: {config.reference_source}',
            [(key, stamp, inside(key)) for key, _, stamp in states],
            period_s=robot.ipo_period_s,
            origin_ns=span.origin,
            first=span.firsts[''],
        )
        states = sorted(states[stretch], key=lambda item: item[0])
    check_timing(path, config.topics, config.timing, [item[:2] for item in keyed], span.firsts)
    by_key: dict[int, Cycle] = {}
    for key, topic_index, data, _ in sorted(keyed, key=lambda item: (item[0], item[3])):
        by_key.setdefault(key, Cycle(0, key)).messages.append((topic_index, data))
    if has_reference and states:
        keep = [inside(key) for key, _, _ in states]
        references = _reference_bytes(config, robot, [data for _, data, _ in states], keep)
        for (key, _, _), reference in zip(states, references, strict=True):
            if reference is not None:
                by_key.setdefault(key, Cycle(0, key)).messages.append((-1, reference))
    if not by_key:
        raise ConfigError(
            f'{path}: nothing to play after start_offset_s {config.start_offset_s} s '
            f'(duration_s {config.duration_s} s)'
        )
    cycles = [by_key[key] for key in sorted(by_key)]
    origin = cycles[0].stamp_ns
    for cycle in cycles:
        cycle.offset_ns = cycle.stamp_ns - origin
    return ReplayPlan(
        tuple(config.topics),
        tuple(types[t] for t in config.topics),
        cycles,
        round(robot.ipo_period_s * NS_PER_S),
        (
            *span.warnings,
            *stamp_notes(
                path,
                config.topics,
                config.timing,
                [([i for i, _ in cycle.messages], cycle.stamp_ns) for cycle in cycles],
                None if has_reference else robot.ipo_period_s,
            ),
        ),
    )
