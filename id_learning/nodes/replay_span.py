"""Checks of the replay's span: its timing, every requested topic plays, an unpaired tail.

Timing (``check_stamp_order``, ``source_stretch``): the stamps the replay reads pass train's check
first (``dataset.plausibility.check_stamps``), in play order (the bag's, or header-stamp order
where a clock step on the recorder stepped the log times back: ``replay_plan``): a stamp that
repeats or goes backwards refuses the bag, naming the sample (the replay never re-sorts stamps a
sender put out of order), and the reference source must be one stretch without holes (longer than
``MAX_GAP_PERIODS`` IPO periods, as train) across the played span: a hole in it is named, with the
spans before and after it to play instead; a hole in the padding read around the span only ends the
padding there. Without that, a hole or a swapped stamp shows up later as an acceleration or a
consistency error that names neither.

Sampling (``refuse_off_period``): the reference source's stamps must keep the robot's IPO period
(``dataset.content.sampling_problem``, train's rule): the reference is filtered and differentiated
for that period, so a bag sampled at another is refused with both periods; without a reference
the replay only warns. Log times (``check_log_times``): with ``timing: log_time`` they schedule
the cycles, so log times that do not advance (all equal, or running backwards) refuse the bag.

Kept apart from ``replay.py`` (no rclpy here): the checks see only header stamps (read with
``header_stamp_ns``), keys, topic indices and counts.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from id_learning.bag.messages import typestore
from id_learning.dataset.content import sampling_problem
from id_learning.dataset.plausibility import check_stamps
from id_learning.errors import BagError, DatasetError
from id_learning.predictor.guards import stamp_problem

__all__ = [
    'LOG_TIME_STUCK_SHARE',
    'MAX_GAP_PERIODS',
    'check_log_times',
    'check_stamp_order',
    'check_timing',
    'check_topics_order',
    'check_topics_play',
    'header_stamp_ns',
    'refuse_off_period',
    'source_stretch',
    'stamp_notes',
    'unpaired_tail',
]

#: The longest silence within a played stretch [IPO periods]: train's (``load_recording``).
MAX_GAP_PERIODS = 3.0
NS_PER_S = 1_000_000_000
#: Log times that do not advance in more than this share of a topic's steps cannot schedule it.
LOG_TIME_STUCK_SHARE = 0.1


def check_log_times(path: Path, topics: Sequence[str], keyed: Sequence[tuple[int, int]]) -> None:
    """Refuse ``timing: log_time`` on a topic whose log times do not advance.

    Args:
        path: the bag (for the message).
        topics: the played topics.
        keyed: (log time [ns], topic index) of each message in the span, as read.

    Raises:
        BagError: names the bag, the topic and what its log times do; suggests the stamps.
    """
    for k, topic in enumerate(topics):
        logs = np.array([key for key, index in keyed if index == k], dtype=np.int64)
        steps = np.diff(logs)
        stuck = int(np.count_nonzero(steps <= 0))
        if not steps.size or stuck <= LOG_TIME_STUCK_SHARE * steps.size:
            continue
        what = (
            f'all {logs.size} log times are {int(logs[0])} ns'
            if stuck == steps.size and not steps.any()
            else f'log times repeat in {int(np.count_nonzero(steps == 0))} and run backwards in '
            f'{int(np.count_nonzero(steps < 0))} of {steps.size} steps'
        )
        raise BagError(
            f'{path}: {topic}: {what}, so timing:=log_time cannot pace a real-time replay (it '
            'would publish them in bursts): use timing:=stamp (the header stamps)'
        )


def refuse_off_period(where: str, stamps_ns: Sequence[int], period_s: float) -> None:
    """Refuse a reference source sampled at another period than the robot's IPO period.

    Raises:
        BagError: ``content.sampling_problem``'s line (both periods), and why nothing plays.
    """
    problem = sampling_problem(np.asarray(stamps_ns, dtype=np.int64), period_s, where)
    if problem is not None:
        raise BagError(
            f'{problem}; nothing is played: the reference is filtered and differentiated for '
            'the IPO period'
        )


def header_stamp_ns(data: bytes, msgtype: str, where: str) -> int | None:
    """The header stamp of one message [ns], None when its type has no header.

    Raises:
        BagError: the bytes are no message of the topic's type, or its stamp is invalid
            (``nanosec`` >= 1e9 or ``sec`` < 0; names ``where``).
    """
    try:
        msg = typestore().deserialize_cdr(data, msgtype)
    except Exception as err:  # rosbags raises SerdeError and others on foreign bytes
        raise BagError(f'{where}: not a valid {msgtype} ({type(err).__name__}: {err})') from err
    header = getattr(msg, 'header', None)
    if header is None:
        return None
    sec, nanosec = int(header.stamp.sec), int(header.stamp.nanosec)
    problem = stamp_problem(sec, nanosec)
    if problem is not None:  # folded in, it would be another time: refused, as the predictor does
        raise BagError(
            f'{where}: invalid header stamp: {problem}; nothing is played from a bag whose '
            'stamps cannot be placed (recorded by a sender with a broken clock?)'
        )
    return sec * NS_PER_S + nanosec


def _counted_from(first: int) -> str:
    return f' (samples counted from its message {first}, the first read for the span)' * (
        first > 0
    )


def check_topics_order(
    path: Path,
    topics: Sequence[str],
    keyed: Sequence[tuple[int, int]],
    firsts: Mapping[str, int],
) -> None:
    """``check_stamp_order`` for each played topic whose cycles its header stamps make.

    Args:
        path: the bag (for messages).
        topics: the played topics.
        keyed: (stamp [ns], topic index) of each message in the span, in play order.
        firsts: each topic's message number (in play order) of its first message in the span.

    Raises:
        BagError: names the topic, the sample and both stamps.
    """
    for k, topic in enumerate(topics):
        stamps = [key for key, index in keyed if index == k]
        remedy = '; timing:=log_time plays it in log-time order'
        check_stamp_order(f'{path}: {topic}', stamps, first=firsts.get(topic, 0), remedy=remedy)


def check_stamp_order(
    where: str, stamps_ns: Sequence[int] | np.ndarray, *, first: int = 0, remedy: str = ''
) -> None:
    """Refuse stamps that repeat or go backwards in play order (train's check).

    Args:
        where: the bag and topic, for the message.
        stamps_ns: the topic's header stamps in play order (``replay_plan``) [ns].
        first: the topic's message number of ``stamps_ns[0]`` (for the message).
        remedy: what plays such a bag, appended to the message.

    Raises:
        BagError: names the sample and both stamps (``check_stamps``).
    """
    try:
        check_stamps(
            np.asarray(stamps_ns, dtype=np.int64), 1.0, np.inf, where + _counted_from(first)
        )
    except DatasetError as err:
        raise BagError(
            f'{err}: nothing is played (the replay never re-sorts stamps a sender put out of '
            'order; with timing:=stamp it plays in header-stamp order only where the log times '
            f'step back too: a clock step on the recorder){remedy}'
        ) from err


def source_stretch(
    where: str,
    read: Sequence[tuple[int, int, bool]],
    *,
    period_s: float,
    origin_ns: int,
    first: int = 0,
) -> slice:
    """The stretch of the reference source, as read, that the reference is built from.

    The stamps must increase (``check_stamp_order``). A hole (a step longer than
    ``MAX_GAP_PERIODS`` periods) before the span's first sample or after its last ends the
    padding there; one inside the span refuses the bag.

    Args:
        where: the bag and topic, for messages.
        read: per message of the source in play order (the span and the padding around it):
            its key (its stamp, or its log time with ``timing: log_time``) [ns], its header
            stamp [ns], and whether it is in the played span.
        period_s: the IPO period [s].
        origin_ns: the key start_offset_s counts from [ns].
        first: the topic's message number of ``stamps_ns[0]`` (for messages).

    Raises:
        BagError: a stamp repeats or goes backwards; a hole lies inside the span (named as train
            names it, with the start offset or duration that plays around it); the stretch is
            sampled off the IPO period (``refuse_off_period``).
    """
    remedy = (
        '; timing:=log_time with reference_mode:=none plays the bag as recorded, without a '
        'reference'
    )
    keys_ns = [key for key, _, _ in read]
    stamps = np.array([stamp for _, stamp, _ in read], dtype=np.int64)
    check_stamp_order(where, stamps, first=first, remedy=remedy)
    inside = np.flatnonzero([is_in for _, _, is_in in read])
    if not len(inside):
        return slice(0, len(stamps))
    after_holes = np.flatnonzero(np.diff(stamps) > MAX_GAP_PERIODS * period_s * NS_PER_S) + 1
    begin, end = 0, len(stamps)
    for k in after_holes.tolist():
        if k <= inside[0]:  # everything before the hole is padding
            begin = k
        elif k > inside[-1]:  # everything after it
            end = k
            break
        else:
            before_s, after_s = ((keys_ns[j] - origin_ns) / NS_PER_S for j in (k - 1, k))
            offset_s = (keys_ns[inside[0]] - origin_ns) / NS_PER_S
            instead = f'start_offset_s {after_s:.3f} or more plays the part after it'
            if before_s > offset_s:
                instead = (
                    f'duration_s {before_s - offset_s:.3f} or less plays the part before it, '
                    + instead
                )
            try:
                check_stamps(
                    stamps[begin : k + 1],
                    period_s,
                    MAX_GAP_PERIODS,
                    where + _counted_from(first + begin),
                )
            except DatasetError as err:
                raise BagError(
                    f'{err}; the played span holds this hole (from {before_s:.3f} s to '
                    f"{after_s:.3f} s after the bag's start), across which no reference can be "
                    f'built: {instead}'
                ) from err
    refuse_off_period(where, np.sort(stamps[begin:end]).tolist(), period_s)
    return slice(begin, end)


def check_topics_play(
    path: Path,
    topics: Sequence[str],
    played: Sequence[int],
    listed: dict[str, int],
    span: str,
) -> None:
    """Refuse when a requested topic has no message in the played span.

    Args:
        path: the bag (for the message).
        topics: the requested topics (bag topics, then the reference source if any).
        played: messages of each topic in the span, in the order of ``topics``.
        listed: message counts metadata.yaml gives per topic.
        span: the span in words (start offset and duration).

    Raises:
        BagError: names the first such topic and what metadata.yaml claims for it.
    """
    for topic, count in zip(topics, played, strict=True):
        if count:
            continue
        claim = listed.get(topic, 0)
        why = (
            f'metadata.yaml lists {claim} message(s) of it in the whole bag'
            if claim
            else 'the bag holds none'
        )
        raise BagError(
            f'{path}: topic {topic} yields no message in the played span ({span}); {why}; '
            'nothing would be published on it: drop it from topics or fix the bag'
        )


def unpaired_tail(
    path: Path, topics: Sequence[str], cycles: Sequence[Sequence[int]], stamps_ns: Sequence[int]
) -> str | None:
    """A warning when the last cycles lack some topics (an interrupted recording), else None.

    Args:
        path: the bag (for the message).
        topics: the bag topics played.
        cycles: each cycle's topic indices (the reference's -1 is ignored), in time order.
        stamps_ns: each cycle's stamp [ns].
    """
    everything = set(range(len(topics)))
    last_full = max((k for k, held in enumerate(cycles) if everything <= set(held)), default=None)
    if last_full is None or len(topics) < 2:
        return None
    tail = [k for k in range(last_full + 1, len(cycles)) if any(i >= 0 for i in cycles[k])]
    if not tail:
        return None
    missing = sorted({topics[i] for k in tail for i in everything - set(cycles[k])})
    return (
        f'{path}: unpaired tail: the last {len(tail)} cycle(s) (stamps from '
        f'{stamps_ns[tail[0]]} ns) lack {", ".join(missing)}, as after an interrupted '
        'recording; they are played as they are (train refuses such a tail unless '
        '--trim-unpaired-tail)'
    )


def check_timing(
    path: Path,
    topics: Sequence[str],
    timing: str,
    keyed: Sequence[tuple[int, int]],
    firsts: Mapping[str, int],
) -> None:
    """Refuse what the timing cannot play: stamps out of order ('stamp'), stuck log times."""
    if timing == 'stamp':
        check_topics_order(path, topics, keyed, firsts)
    else:
        check_log_times(path, topics, keyed)


def stamp_notes(
    path: Path,
    topics: Sequence[str],
    timing: str,
    cycles: Sequence[tuple[Sequence[int], int]],
    period_s: float | None,
) -> tuple[str, ...]:
    """What a replay timed by stamps warns of: an unpaired tail, and cycles off the IPO period.

    Log times differ per topic: only stamps pair messages, so ``timing: log_time`` has none.

    Args:
        cycles: per cycle, the indices of the topics it holds and its stamp [ns].
        period_s: the IPO period to hold the cycle stamps against; None where a reference is
            built (its source was refused off the period already).
    """
    if timing != 'stamp':
        return ()
    stamps = [stamp for _, stamp in cycles]
    tail = unpaired_tail(path, topics, [held for held, _ in cycles], stamps)
    off = None
    if period_s is not None:
        found = sampling_problem(
            np.array(stamps, dtype=np.int64), period_s, f'{path}: cycle stamps'
        )
        off = None if found is None else f'{found}; played as recorded'
    return tuple(note for note in (tail, off) if note)
