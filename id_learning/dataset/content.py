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
- With the robot, each joint's label (in N*m: currents times gear ratio and torque constant) is
  regressed on the URDF's gravity torque at the recorded positions (both centred), where that
  torque varies enough to decide (standard deviation at least ``NOMINAL_MIN_SHARE`` of the torque
  limit) and explains the label (|correlation| at least ``NOMINAL_MIN_CORRELATION``). The slope
  is near +1 on a sound recording (friction, a payload, a balancer spring move it, hence the
  generous ``NOMINAL_SLOPE_FACTOR``); near -1 names a sign (the joint's current sign, or gravity
  acting otherwise than in the URDF: a robot mounted upside down), a factor 1e-3 or 1e3 a unit or
  scale. Warned (``gravity_findings``). So is, on any joint that moves (gravity or not), a
  label whose 99th percentile magnitude stays below ``TINY_LABEL_SHARE`` of the joint's torque
  limit: friction alone takes more to move a joint, so the currents' unit or the drive train
  (a gear ratio written as joint turns per motor turn) is off.
- A label that is one-signed and comes down to zero without crossing it while its joint moves
  both ways has lost its sign (a magnitude recorded): warned (``sign_findings``).

``sampling_problem`` is the timing counterpart inspect and the replay share: a topic sampled at
another period than the robot's IPO period.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from id_learning.dataset.sampling_grid import (
    SAMPLING_TOLERANCE,
    grid_slots,
    sampling_problem,
)
from id_learning.errors import DatasetError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import torque_per_ampere

__all__ = [
    'NOMINAL_MIN_CORRELATION',
    'NOMINAL_MIN_SHARE',
    'NOMINAL_SLOPE_FACTOR',
    'SAMPLING_TOLERANCE',
    'SATURATION_LEVEL_RATIO',
    'SATURATION_MIN_SAMPLES',
    'SATURATION_MIN_SHARE',
    'SATURATION_NEIGHBOURS',
    'SIGN_LOST_OPPOSITE_SHARE',
    'SIGN_LOST_QUANTILE',
    'SIGN_LOST_REVERSAL_SHARE',
    'SIGN_LOST_ZERO_SHARE',
    'STILL_NOISE_FACTOR',
    'STILL_SPAN_RAD',
    'TINY_LABEL_SHARE',
    'Finding',
    'GravityTorque',
    'check_content',
    'gravity_findings',
    'gravity_in_label_unit',
    'grid_slots',
    'label_findings',
    'motion_findings',
    'nominal_findings',
    'position_noise',
    'sampling_problem',
    'saturated_levels',
    'sign_findings',
    'tiny_label_findings',
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
#: The nominal gravity torque judges a joint's label only where its standard deviation over the
#: recording reaches this share of the joint's torque limit ...
NOMINAL_MIN_SHARE = 0.005
#: ... and where it explains the label: |correlation| at least this.
NOMINAL_MIN_CORRELATION = 0.5
#: A slope of the label on the nominal torque within [1 / this, this] passes.
NOMINAL_SLOPE_FACTOR = 30.0
#: At most this many samples, evenly strided, go through the nominal model.
NOMINAL_MAX_SAMPLES = 5000
#: A moving joint's label whose 99th percentile magnitude [N*m] is below this share of its torque
#: limit is too small for any drive: friction alone takes more (percents of the limit).
TINY_LABEL_SHARE = 1e-3


@dataclass(frozen=True)
class Finding:
    """What one joint's signal lacks.

    Attributes:
        joint: the joint's name ('' for a finding about every joint).
        kind: 'constant' (label), 'saturated' (label), 'still' (one joint), 'no_motion' (all),
            'nominal_sign' or 'nominal_scale' (label against the nominal model), 'sign_lost'.
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


def nominal_findings(
    label_nm: np.ndarray,
    nominal_nm: np.ndarray,
    joints: Sequence[str],
    torque_limit: np.ndarray,
    *,
    quantity: str = 'motor current',
) -> list[Finding]:
    """Joints whose label (N, n) [N*m] contradicts a nominal torque (N, n) in sign or scale.

    Each column pair is centred and the label regressed on the nominal torque; a joint is judged
    only where the nominal torque varies enough and explains the label (module docstring).
    """
    label_nm = np.asarray(label_nm, dtype=float)
    nominal_nm = np.asarray(nominal_nm, dtype=float)
    findings: list[Finding] = []
    for j, joint in enumerate(joints):
        x = nominal_nm[:, j] - nominal_nm[:, j].mean()
        y = label_nm[:, j] - label_nm[:, j].mean()
        spread, label_spread = float(x.std()), float(y.std())
        if spread < NOMINAL_MIN_SHARE * float(torque_limit[j]) or not label_spread > 0:
            continue
        correlation = float(x @ y) / (x.size * spread * label_spread)
        if abs(correlation) < NOMINAL_MIN_CORRELATION:
            continue
        slope = float(x @ y) / float(x @ x)
        head = (
            f'{joint}: {quantity} against the URDF gravity torque at the recorded positions: '
            f'slope {slope:.3g} (near +1 expected; correlation {correlation:.2f}, gravity '
            f'torque std {spread:.3g} N*m)'
        )
        if abs(slope) < 1 / NOMINAL_SLOPE_FACTOR or abs(slope) > NOMINAL_SLOPE_FACTOR:
            factor = 10.0 ** round(float(np.log10(abs(slope))))
            unit = (
                "the currents' unit (kA or mA recorded as A?) or the drives' gear_ratio and "
                'torque_constant'
                if quantity == 'motor current'
                else "the torques' unit (kN*m or N*mm recorded as N*m?)"
            )
            text = f'{head}: the label is about {factor:g} x the nominal torque: check {unit}'
            findings.append(Finding(joint, 'nominal_scale', False, text))
        if slope < 0:
            text = (
                f'{head}: the sign is wrong: either the {quantity} sign of this joint is flipped, '
                'or gravity acts otherwise than in the URDF (the robot mounted upside down or '
                'on a wall while the URDF stands it on the floor)'
            )
            findings.append(Finding(joint, 'nominal_sign', False, text))
    return findings


#: A label on one side of zero but for at most this share of the samples is one-signed.
SIGN_LOST_OPPOSITE_SHARE = 1e-3
#: ... and it keeps coming to zero: its 1 % quantile of magnitude (exact zeros, a drive switched
#: off, left out) is at most this share of its 99 % quantile. A magnitude spends a share of its
#: time near zero at every crossing it folded; a label held off zero, however noisy, does not.
SIGN_LOST_ZERO_SHARE = 0.05
SIGN_LOST_QUANTILE = 0.01
#: A joint moves both ways when it goes back by this share of its span after rising and rises
#: by it after going back (largest retreat from a running extreme).
SIGN_LOST_REVERSAL_SHARE = 0.2


def _moves_both_ways(q: np.ndarray) -> bool:
    span = float(q.max() - q.min())
    if span < 10 * STILL_SPAN_RAD:
        return False
    back = float(np.max(np.maximum.accumulate(q) - q))
    forth = float(np.max(q - np.minimum.accumulate(q)))
    return min(back, forth) >= SIGN_LOST_REVERSAL_SHARE * span


def _held_on_one_side(gravity: np.ndarray, low: float) -> bool:
    """Gravity keeps one sign along the recording, at least half as far from zero as ``low``."""
    finite = gravity[np.isfinite(gravity)]
    one_signed = bool(finite.size) and (bool(np.all(finite > 0)) or bool(np.all(finite < 0)))
    return one_signed and float(np.min(np.abs(finite))) >= 0.5 * low


def gravity_in_label_unit(
    position: np.ndarray, robot: RobotConfig, gravity: GravityTorque, quantity: str
) -> np.ndarray:
    """The URDF's gravity torque at (at most ``NOMINAL_MAX_SAMPLES`` of) the positions (N, n).

    In the label's unit (A or N*m); rows with a non-finite position are left out.
    """
    position = np.asarray(position, dtype=float)
    position = position[np.isfinite(position).all(axis=1)]
    position = position[:: max(1, -(-len(position) // NOMINAL_MAX_SAMPLES))]
    torque = np.asarray(gravity(position), dtype=float)
    if quantity == 'motor current':
        torque = torque / torque_per_ampere(robot.drives)
    return torque


def sign_findings(
    position: np.ndarray,
    label: np.ndarray,
    joints: Sequence[str],
    *,
    quantity: str = 'motor current',
    unit: str = 'A',
    held: np.ndarray | None = None,
) -> list[Finding]:
    """Joints whose label lost its sign: one-signed, reaching zero, while the joint goes both ways.

    A joint that moves back and forth needs torque of both signs, unless gravity or a spring
    holds it on one side, and then its torque stays away from zero. A label that keeps coming
    down to zero and turning back at it, never crossing (noise would cross), is a magnitude:
    ``|I|`` or ``-|I|`` recorded for the signed value. Warned: the model learns nothing true
    from it. ``position``, ``label``: (N, n) [rad] and [``unit``]; non-finite rows left out.
    ``held``: (M, n) the URDF's gravity torque along the recording (at its positions, or every
    k-th of them) in the label's unit, where known: a joint that gravity alone holds on one
    side, as far from zero as the label comes, is one-signed by nature and not judged here
    (``gravity_findings`` judges its sign).
    """
    position = np.asarray(position, dtype=float)
    label = np.asarray(label, dtype=float)
    rows = np.isfinite(position).all(axis=1) & np.isfinite(label).all(axis=1)
    position, label = position[rows], label[rows]
    findings: list[Finding] = []
    for j, joint in enumerate(joints):
        column = label[:, j]
        if column.size < 3 or not np.any(column):
            continue
        positive, negative = int((column > 0).sum()), int((column < 0).sum())
        if min(positive, negative) > SIGN_LOST_OPPOSITE_SHARE * column.size:
            continue
        magnitude = np.abs(column[column != 0])  # exact zeros: a drive switched off
        if magnitude.size < 3:
            continue
        low, high = np.quantile(magnitude, [SIGN_LOST_QUANTILE, 1 - SIGN_LOST_QUANTILE])
        if low > SIGN_LOST_ZERO_SHARE * high:
            continue  # held away from zero (gravity, a spring), noise or not
        if held is not None and _held_on_one_side(np.asarray(held, dtype=float)[:, j], low):
            continue
        if not _moves_both_ways(position[:, j]):
            continue
        side, extreme = ('<= 0', column.max()) if negative > positive else ('>= 0', column.min())
        others = min(positive, negative)
        where = 'in every sample' if not others else f'in all but {others} samples'
        text = (
            f'{joint}: the {quantity} is {side} {where} (it comes to {extreme + 0.0:.4g} '
            f'{unit} and turns back, never crossing zero) while the joint moves both ways: its '
            f'sign is lost (a magnitude such as |I| or -|I| recorded); record the signed '
            f'{quantity}'
        )
        findings.append(Finding(joint, 'sign_lost', False, text))
    return findings


#: The URDF's gravity torque (N, n) [N*m] at positions (N, n) [rad]: the dataset layer takes it
#: from its caller (``physics.rigid_body.RigidBodyDynamics.gravity``), it builds no dynamics.
GravityTorque = Callable[[np.ndarray], np.ndarray]


def gravity_findings(
    position: np.ndarray,
    label: np.ndarray,
    robot: RobotConfig,
    gravity: GravityTorque,
    *,
    quantity: str = 'motor current',
) -> list[Finding]:
    """``nominal_findings`` against the gravity torque of the robot's URDF.

    Args:
        position: (N, n) positions [rad] in the robot's joint order.
        label: (N, n) currents [A] ('motor current') or joint torques [N*m].
        gravity: the robot's gravity torque at positions (``GravityTorque``).
        quantity: what the label is.

    Rows with a non-finite value are left out; at most ``NOMINAL_MAX_SAMPLES`` rows are used.
    """
    position = np.asarray(position, dtype=float)
    label = np.asarray(label, dtype=float)
    rows = np.isfinite(position).all(axis=1) & np.isfinite(label).all(axis=1)
    position, label = position[rows], label[rows]
    if len(position) < 3:
        return []
    stride = -(-len(position) // NOMINAL_MAX_SAMPLES)
    position, label = position[::stride], label[::stride]
    if quantity == 'motor current':
        label = label * torque_per_ampere(robot.drives)
    nominal = gravity(position)
    findings = nominal_findings(
        label, nominal, robot.joints, robot.limits.torque, quantity=quantity
    )
    scaled = {finding.joint for finding in findings if finding.kind == 'nominal_scale'}
    tiny = tiny_label_findings(position, label, robot, quantity=quantity)
    return findings + [finding for finding in tiny if finding.joint not in scaled]


def tiny_label_findings(
    position: np.ndarray, label_nm: np.ndarray, robot: RobotConfig, *, quantity: str
) -> list[Finding]:
    """Moving joints whose label (N, n) [N*m] stays below ``TINY_LABEL_SHARE`` of the limit."""
    findings = []
    still = {finding.joint for finding in motion_findings(position, robot.joints)}
    for j, joint in enumerate(robot.joints):
        if joint in still or not label_nm.shape[0]:
            continue
        size = float(np.percentile(np.abs(label_nm[:, j]), 99))
        limit = float(robot.limits.torque[j])
        if size < TINY_LABEL_SHARE * limit:
            unit = (
                "the currents' unit (mA recorded as A?) or the drive's gear_ratio (motor turns "
                'per joint turn) and torque_constant'
                if quantity == 'motor current'
                else "the torques' unit (N*mm recorded as N*m?)"
            )
            text = (
                f'{joint}: the {quantity} as joint torque reaches only {size:.3g} N*m (99th '
                f'percentile) while the joint moves: {size / limit:.2g} of its torque limit '
                f'{limit:g} N*m, less than friction alone takes; check {unit}'
            )
            findings.append(Finding(joint, 'nominal_scale', False, text))
    return findings


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
    nominal: tuple[RobotConfig, GravityTorque] | None = None,
    held_by: tuple[RobotConfig, GravityTorque] | None = None,
) -> tuple[str, ...]:
    """Refuse a recording without signal, log and return the warnings (module docstring).

    Args:
        position: (N, n) positions [rad].
        label: (N, n) the label's recorded values (currents [A] or joint torques [N*m]), or None.
        where: the recording (bag path), for the messages.
        warn: log the warnings (they are returned either way).
        nominal: the robot (in whose joint order ``joints`` are) and its gravity torque: adds
            ``gravity_findings``, and informs the sign check as ``held_by`` does.
        held_by: the robot and its gravity torque for the sign check alone: a joint gravity
            holds on one side is not suspected of a lost sign (``sign_findings``).

    Raises:
        DatasetError: a label column is constant, or no joint moves (every such line).
    """
    findings = motion_findings(position, joints, duration_s=duration_s)
    if label is not None:
        findings += label_findings(
            label, joints, quantity=quantity, unit=unit, duration_s=duration_s
        )
    refusals = [finding.text for finding in findings if finding.refuses]
    if label is not None and not refusals:
        holder = nominal or held_by
        held = None if holder is None else gravity_in_label_unit(position, *holder, quantity)
        findings += sign_findings(position, label, joints, quantity=quantity, unit=unit, held=held)
    if nominal is not None and label is not None and not refusals:
        findings += gravity_findings(position, label, *nominal, quantity=quantity)
    if refusals:
        raise DatasetError(f'{where}: ' + '; '.join(refusals))
    warnings = tuple(finding.text for finding in findings)
    for text in warnings if warn else ():
        _LOG.warning('%s: %s', where, text)
    return warnings
