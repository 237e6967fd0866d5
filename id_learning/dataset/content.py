"""Signal content: whether a recording holds what identification needs, joint by joint.

The plausibility gate (``plausibility``) and the consistency gate (``consistency``) judge whether
each sample could be real; this module judges whether the recording as a whole carries signal.
One rule for every door: ``load_recording`` (so train, evaluate, diagnose and demo) refuses or
warns with these lines, ``inspect`` lists them as problems.

- A label (motor current, or measured joint torque) that holds one value in every sample carries
  no torque: refused, naming the joint and the value ("exactly 0 A in every sample").
- A label that sits at its largest or smallest value in a share of the samples far above any
  other value's share has flat tops: the drive saturated, or the logger clipped it. Warned, naming
  the joint, the value and the share. Quantised labels hold each level for a while too, but near
  an unclipped peak the levels below the top hold about as long (``SATURATION_LEVEL_RATIO``); an
  extreme of exactly 0 is no saturation (a drive switched off).
- A joint whose position spans less than ``STILL_SPAN_RAD`` (about 20 counts of a 17-bit
  joint-side encoder), or less than ``STILL_NOISE_FACTOR`` times its position noise, does not
  move: its friction and inertia cannot be identified (warned). When no joint moves there is
  nothing to identify: refused.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from id_learning.errors import DatasetError

__all__ = [
    'SATURATION_LEVEL_RATIO',
    'SATURATION_MIN_SAMPLES',
    'SATURATION_MIN_SHARE',
    'SATURATION_NEIGHBOURS',
    'STILL_NOISE_FACTOR',
    'STILL_SPAN_RAD',
    'Finding',
    'check_content',
    'label_findings',
    'motion_findings',
    'position_noise',
    'saturated_levels',
]

_LOG = logging.getLogger(__name__)

#: A joint whose position spans less than this [rad] over a recording does not move.
STILL_SPAN_RAD = 1e-3
#: ... nor does one whose span stays below this multiple of its position noise (the range of
#: white noise over 10^7 samples is about 11.4 standard deviations).
STILL_NOISE_FACTOR = 12.0
#: A label sitting at its extreme in at least this share of the samples may be saturated ...
SATURATION_MIN_SHARE = 0.01
#: ... and in at least this many samples ...
SATURATION_MIN_SAMPLES = 10
#: ... when none of the values next to it is held more than 1 / this as often ...
SATURATION_LEVEL_RATIO = 5.0
#: ... of this many values next to it.
SATURATION_NEIGHBOURS = 3


@dataclass(frozen=True)
class Finding:
    """What one joint's signal lacks.

    Attributes:
        joint: the joint's name ('' for a finding about every joint).
        kind: 'constant' (label), 'saturated' (label), 'still' (one joint), 'no_motion' (all).
        refuses: training and diagnosis refuse the recording for it (else a warning).
        text: one line naming the joint, the value and the span.
    """

    joint: str
    kind: str
    refuses: bool
    text: str


def _span_text(duration_s: float | None, n_samples: int) -> str:
    if duration_s is None:
        return f'all {n_samples} samples'
    return f'all {n_samples} samples, {duration_s:.1f} s'


def label_findings(
    values: np.ndarray,
    joints: Sequence[str],
    *,
    quantity: str = 'motor current',
    unit: str = 'A',
    duration_s: float | None = None,
) -> list[Finding]:
    """Constant and saturated label columns of ``values`` (N, n); non-finite values are ignored.

    Args:
        quantity: the label's name for the text ('motor current', 'joint torque').
        unit: its unit for the text.
        duration_s: the recording's length, for the text.
    """
    values = np.asarray(values, dtype=float)
    findings: list[Finding] = []
    zero = [
        joint for j, joint in enumerate(joints) if values.shape[0] and np.all(values[:, j] == 0.0)
    ]
    if len(joints) > 1 and len(zero) == len(joints):
        text = (
            f'{quantity} is exactly 0 {unit} in every sample of every joint ({", ".join(zero)}; '
            f'{_span_text(duration_s, values.shape[0])}): no torque was recorded'
        )
        return [Finding('', 'constant', True, text)]
    for j, joint in enumerate(joints):
        column = values[:, j]
        finite = column[np.isfinite(column)]
        if finite.size == 0:
            continue
        low, high = float(finite.min()), float(finite.max())
        span = _span_text(duration_s, finite.size)
        if low == high:
            if low == 0.0:
                text = (
                    f'{joint}: {quantity} is exactly 0 {unit} in every sample ({span}): no torque '
                    'was recorded'
                )
            else:
                text = (
                    f'{joint}: {quantity} is {low:.6g} {unit} in every sample ({span}): a '
                    'constant carries no torque (a placeholder, or a signal that was not recorded)'
                )
            findings.append(Finding(joint, 'constant', True, text))
            continue
        levels = saturated_levels(finite)
        if levels:
            held = ' and at '.join(
                f'{level:.6g} {unit} in {100 * share:.3g} %' for level, share in levels
            )
            findings.append(
                Finding(
                    joint,
                    'saturated',
                    False,
                    f'{joint}: {quantity} sits at {held} of the {finite.size} samples (flat '
                    'tops at its extremes): clipped by the drive or the logger, so the label is '
                    'wrong wherever the torque went beyond',
                )
            )
    return findings


def saturated_levels(values: np.ndarray) -> list[tuple[float, float]]:
    """(level, share of the samples) of each extreme a finite column (N,) is clipped at.

    An extreme is clipped when at least ``SATURATION_MIN_SHARE`` of the samples (and
    ``SATURATION_MIN_SAMPLES``) sit exactly at it and each of the ``SATURATION_NEIGHBOURS``
    values next to it is held at most 1 / ``SATURATION_LEVEL_RATIO`` as often (near an unclipped
    peak of a quantised signal the levels below the top are held about as long); an extreme of
    0 is never one.
    """
    values = np.asarray(values, dtype=float)
    n = values.size
    if n < SATURATION_MIN_SAMPLES:
        return []
    levels, counts = np.unique(values, return_counts=True)
    if levels.size < 2:
        return []
    k = SATURATION_NEIGHBOURS
    found = []
    for level, count, neighbours in (
        (levels[-1], counts[-1], counts[-1 - k : -1]),
        (levels[0], counts[0], counts[1 : 1 + k]),
    ):
        if (
            level != 0.0
            and count >= max(SATURATION_MIN_SHARE * n, SATURATION_MIN_SAMPLES)
            and count >= SATURATION_LEVEL_RATIO * int(neighbours.max())
        ):
            found.append((float(level), float(count / n)))
    return found


def position_noise(q: np.ndarray) -> float:
    """Robust estimate of white noise on a finite position column (N,) [rad].

    The median absolute deviation of the second differences (white noise of standard deviation
    s gives second differences of standard deviation s * sqrt(6); a smooth motion adds little).
    """
    q = np.asarray(q, dtype=float)
    if q.size < 3:
        return 0.0
    d2 = np.diff(q, n=2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def motion_findings(
    position: np.ndarray, joints: Sequence[str], *, duration_s: float | None = None
) -> list[Finding]:
    """Joints of ``position`` (N, n) [rad] that do not move; one refusal when none moves.

    Non-finite values are ignored; a column without finite values is not judged.
    """
    position = np.asarray(position, dtype=float)
    still: list[tuple[str, float, float]] = []
    judged = 0
    for j, joint in enumerate(joints):
        column = position[:, j]
        finite = column[np.isfinite(column)]
        if finite.size < 2:
            continue
        judged += 1
        span = float(finite.max() - finite.min())
        threshold = max(STILL_SPAN_RAD, STILL_NOISE_FACTOR * position_noise(finite))
        if span < threshold:
            still.append((joint, span, threshold))
    if not still:
        return []
    over = '' if duration_s is None else f' over {duration_s:.1f} s'
    if len(still) == judged and judged == len(joints):
        spans = ', '.join(f'{joint} {span:.3g} rad' for joint, span, _ in still)
        return [
            Finding(
                '',
                'no_motion',
                True,
                f'no joint moves: nothing to identify (every position spans less than '
                f'{STILL_SPAN_RAD:g} rad or its noise{over}: {spans}); record the robot '
                'moving through an excitation trajectory',
            )
        ]
    return [
        Finding(
            joint,
            'still',
            False,
            f'{joint} does not move: its position spans {span:.3g} rad{over} (less than '
            f'{threshold:.3g} rad), so its friction and inertia cannot be identified from this '
            'recording',
        )
        for joint, span, threshold in still
    ]


def check_content(
    position: np.ndarray,
    label: np.ndarray | None,
    joints: Sequence[str],
    *,
    where: str,
    quantity: str = 'motor current',
    unit: str = 'A',
    duration_s: float | None = None,
    warn: bool = True,
) -> tuple[str, ...]:
    """Refuse a recording without signal, log and return the warnings (module docstring).

    Args:
        position: (N, n) positions [rad].
        label: (N, n) the label's recorded values (currents [A] or joint torques [N*m]), or None.
        where: the recording (bag path), for the messages.
        warn: log the warnings (they are returned either way).

    Raises:
        DatasetError: a label column is constant, or no joint moves (every such line).
    """
    findings = motion_findings(position, joints, duration_s=duration_s)
    if label is not None:
        findings += label_findings(
            label, joints, quantity=quantity, unit=unit, duration_s=duration_s
        )
    refusals = [finding.text for finding in findings if finding.refuses]
    if refusals:
        raise DatasetError(f'{where}: ' + '; '.join(refusals))
    warnings = tuple(finding.text for finding in findings)
    for text in warnings if warn else ():
        _LOG.warning('%s: %s', where, text)
    return warnings
