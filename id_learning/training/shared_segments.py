"""Recordings that hold the same samples twice: across bags, segments, or within one.

Each recording (a bag, a segment of one) is split into a training and a test part on its own,
so a motion held twice would put training samples into the test part, and the test scores would
be training scores.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from id_learning.bag.distinct import (
    MIN_SHARED_SAMPLES,
    Samples,
    refuse_shared_samples,
    repeated_samples,
)
from id_learning.dataset.recording import Recording
from id_learning.errors import DatasetError

__all__ = ['refuse_repeats', 'refuse_shared_segments']


_SHARED_WHY = 'the same motion would be in the training and the test part'


def refuse_shared_segments(known: list[Samples], bag: Path, recording: Recording) -> None:
    """Refuse a segment of ``bag`` that holds samples of another segment or of an earlier bag.

    Each segment is split on its own, so a motion in two of them (one bag imported from
    overlapping logs, or a bag cut from another) would be in the training and the test part.
    ``known`` (the earlier bags' segments) gets this bag's segments appended.

    Raises:
        DatasetError: names both bags or segments and the stamps they share.
    """
    segments = recording.segments()
    new: list[Samples] = [
        (
            str(bag) if len(segments) == 1 else f'{bag} segment {k + 1} of {len(segments)}',
            segment.stamps_ns,
            segment.position,
            np.hstack(
                [
                    segment.velocity,
                    *(x for x in (segment.current, segment.joint_torque) if x is not None),
                ]
            ),
        )
        for k, segment in enumerate(segments)
    ]
    for k, samples in enumerate(new):
        refuse_repeats(samples)
        for other in known:
            refuse_shared_samples([other, samples], f'{_SHARED_WHY}; give each recording once')
        for other in new[:k]:
            refuse_shared_samples(
                [other, samples],
                f'{_SHARED_WHY}; the bag holds them twice (an import of logs that overlap): '
                're-import it from logs cut without the overlap',
            )
    known.extend(new)


def refuse_repeats(samples: Samples) -> None:
    """Refuse a recording that holds a stretch of its own samples twice.

    Split into a training and a test part, the copy would put training samples into the test
    part and report training scores as test scores (a looped replay recorded into one bag).

    Raises:
        DatasetError: names the recording and both stretches' stamps.
    """
    first, second = repeated_samples(samples)
    if first.size < MIN_SHARED_SAMPLES:
        return
    shift_s = (int(second[0]) - int(first[0])) * 1e-9
    raise DatasetError(
        f'{samples[0]} holds the same {first.size} samples twice: stamps {int(first[0])} to '
        f'{int(first[-1])} ns again {shift_s:.1f} s later, from {int(second[0])} ns: '
        f'{_SHARED_WHY}; the recording repeats itself (a looped replay recorded into one bag, '
        'or a log appended to itself): record it once, or import only the part before the '
        'repeat'
    )
