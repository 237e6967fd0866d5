"""Checks of the replay's span: every requested topic plays, and an unpaired tail is named.

Kept apart from ``replay.py`` (no rclpy here): the checks see only keys, topic indices and counts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from id_learning.errors import BagError

__all__ = ['check_topics_play', 'unpaired_tail']


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
