"""The plausibility gate: joint motion a real arm can have, checked before anything uses it.

One place for the checks every door applies to recorded or commanded motion (``load_recording``,
so train, evaluate and diagnose; import; the replay's reference; the predictor, one sample at a
time with ``SampleGate``): values finite, stamps strictly increasing (and, for recordings, no gap
longer than a few IPO periods), positions inside the joint limits plus a margin, velocities within
a stated factor of their limits. A violation names where it was found, the sample, its stamp, the
joint, the value and how far it lies beyond the limit. One rule (``reads_as_degrees``,
``beyond_hint``), shared with import, tells what such a value is: a position column is named as
degrees only when its spread in radians is far wider than the joint's range while read as degrees
it fits; a value just beyond a limit is a limit question (the config's limit, an encoder offset,
an arm past a soft limit), never a unit question. What a column is, is judged on its worst sample
(and, for rates, on every joint: one unit serves them all), not on the first beyond: a rate column
whose peak lies over ``RATE_DEGREES_FACTOR`` x its bound while read as degrees it fits is in
degrees (``rate_in_degrees``); a position column that breaks the config's limits but fits the
URDF's names the config's limits, not degrees; a current or torque over ``SCALE_PEAK_FACTOR`` x
its bound is a unit or scale question.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from id_learning.errors import DatasetError
from id_learning.robot.config import JointLimits

__all__ = [
    'ACCELERATION_FACTOR',
    'DEGREES_SPREAD_FACTOR',
    'NEAR_LIMIT_SHARE',
    'PAIRING_SHARE',
    'POSITION_MARGIN_RAD',
    'RATE_DEGREES_FACTOR',
    'SCALE_PEAK_FACTOR',
    'TORQUE_FACTOR',
    'VELOCITY_FACTOR',
    'SampleGate',
    'beyond_hint',
    'beyond_position',
    'beyond_rate',
    'check_accelerations',
    'check_efforts',
    'check_finite',
    'check_limits',
    'check_motion',
    'check_stamps',
    'effort_bound',
    'farthest_position',
    'first_unpaired',
    'rate_in_degrees',
    'reads_as_degrees',
    'urdf_position_limits',
]

#: Where a refusal sends a user whose arm really moves there.
LIMITS_HINT = (
    "the limits are the robot config's (--robot): if the arm's are wider, correct them there"
)
#: Positions may lie this far outside the joint limits [rad] (encoder offsets, overshoot).
POSITION_MARGIN_RAD = 0.05
#: Velocities may reach this multiple of their limits (a drive's short overshoot).
VELOCITY_FACTOR = 1.5
#: Accelerations may reach this multiple of their limits (estimates from differences are noisy).
ACCELERATION_FACTOR = 2.0
#: Measured torques, and currents times gear ratio and torque constant, may reach this multiple of
#: the torque limits (friction and a drive's peak current lie above the rated limit).
TORQUE_FACTOR = 2.0
#: A position column is named as degrees only when its spread in radians is more than this multiple
#: of its joint's range (no motion of that joint) while read as degrees every value fits.
DEGREES_SPREAD_FACTOR = 2.0
#: A rate column is named as degrees only when its peak exceeds this multiple of its bound (in
#: degrees the motion then reaches 10 / 57 of the bound) while read as degrees every value fits.
RATE_DEGREES_FACTOR = 10.0
#: A value beyond a limit by at most this share of the joint's range (positions) or of the limit
#: (velocities, currents, torques) is a limit question, not a unit question.
NEAR_LIMIT_SHARE = 0.1
#: The currents pair with the joint states sample by sample when their stamps differ by at most
#: this share of the sample period: drivers that stamp the two topics separately differ by
#: microseconds, a missed or doubled message by a whole period.
PAIRING_SHARE = 0.1
#: A torque or current whose largest |value| is this multiple of what ``check_efforts`` lets
#: pass is a unit or scale problem (mA for A, a wrong gear ratio), not a limit question.
SCALE_PEAK_FACTOR = 10.0
#: The remedies for a value just beyond a limit.
LIMIT_QUESTION_HINT = (
    "just beyond the limit, a limit question rather than a unit one: check the robot config's "
    'limit against the URDF or datasheet, and for an encoder offset; if the arm went past a soft '
    "limit, widen the config's limit"
)


def reads_as_degrees(q: np.ndarray, lower: float, upper: float) -> bool:
    """Whether a position column taken as radians is clearly in degrees: the one rule for it.

    A column just beyond a limit fits the limits read as degrees too, yet it is a limit question;
    degrees are the better explanation only when the column's spread in radians exceeds
    ``DEGREES_SPREAD_FACTOR`` x the joint's range and, read as degrees, every value fits the limits
    plus ``POSITION_MARGIN_RAD``.

    Args:
        q: (N,) the column's positions as taken [rad]; non-finite values are ignored.
        lower: the joint's lower limit [rad].
        upper: the joint's upper limit [rad].
    """
    finite = np.asarray(q, float)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0 or np.ptp(finite) <= DEGREES_SPREAD_FACTOR * (upper - lower):
        return False
    as_radians = np.radians(finite)
    fits = (as_radians >= lower - POSITION_MARGIN_RAD) & (
        as_radians <= upper + POSITION_MARGIN_RAD
    )
    return bool(fits.all())


def beyond_position(value: float, lower: float, upper: float) -> tuple[float, str]:
    """How far a position [rad] lies beyond its nearer limit: (share of the range, text)."""
    side, limit = ('upper', upper) if value > upper else ('lower', lower)
    excess = abs(value - limit)
    share = excess / (upper - lower)
    return share, (
        f'{excess:.4g} rad beyond the {side} limit {limit:.6g} rad, {100 * share:.3g} % of the '
        "joint's range"
    )


def farthest_position(q: np.ndarray, lower: float, upper: float) -> float:
    """The position in ``q`` (N,) [rad] farthest beyond a limit, or the nearest to one."""
    q = np.asarray(q, float)
    beyond = np.maximum(q - upper, lower - q)
    return float(q[np.nanargmax(beyond)])


def beyond_rate(value: float, limit: float, factor: float, unit: str) -> tuple[float, str]:
    """How far |value| lies beyond ``factor`` x its ``limit``: (share of the limit, text)."""
    excess = abs(value) - factor * limit
    share = excess / limit
    return share, (
        f'{excess:.4g} {unit} beyond {factor:g} x its limit {limit:.4g} {unit}, '
        f'{100 * share:.3g} % of the limit'
    )


def beyond_hint(share: float, degrees: bool, unit_remedy: str, *, what: str = 'degrees') -> str:
    """What a value past the gate most likely is, and its remedy.

    Args:
        share: how far it lies beyond (``beyond_position``, ``beyond_rate``), best the farthest
            value of its column's.
        degrees: ``reads_as_degrees`` of its column (``rate_in_degrees`` of a rate's; False for
            other quantities).
        unit_remedy: what to do when the column is in degrees.
        what: the degree unit for the text ('degrees', 'deg/s').
    """
    if degrees and what == 'degrees':
        return (
            f'read as degrees every value fits the limits, and in radians the values span over '
            f"{DEGREES_SPREAD_FACTOR:g} x the joint's range: {unit_remedy}"
        )
    if degrees:
        return (
            f'a unit question, not a limit one: read as {what} every value fits, and in radians '
            f'the largest lies over {RATE_DEGREES_FACTOR:g} x the bound: {unit_remedy}'
        )
    if share <= NEAR_LIMIT_SHARE:
        return LIMIT_QUESTION_HINT
    return f'check the unit, scale and offset; {LIMITS_HINT}'


class SampleGate:
    """The gate for one sample at a time (online nodes).

    ``check_motion``'s bounds, plus accelerations (when the sample carries them) within
    ``ACCELERATION_FACTOR`` x their limits.

    Args:
        joints: the joint names, in the order of ``limits`` and of the samples.
        limits: the robot's joint limits.
    """

    def __init__(self, joints: tuple[str, ...], limits: JointLimits) -> None:
        self.joints = joints
        self._low = limits.position_lower - POSITION_MARGIN_RAD
        self._high = limits.position_upper + POSITION_MARGIN_RAD
        self._velocity = VELOCITY_FACTOR * limits.velocity
        self._acceleration = ACCELERATION_FACTOR * limits.acceleration

    def violation(self, q: np.ndarray, v: np.ndarray, a: np.ndarray | None) -> str | None:
        """Why no arm of these limits is in this state (finite q, v, a (n,)), or None."""
        outside = (q < self._low) | (q > self._high)
        if outside.any():
            j = int(np.argmax(outside))
            return (
                f'position of {self.joints[j]} {q[j]:.6g} rad is outside its limits '
                f'[{self._low[j] + POSITION_MARGIN_RAD:.4g}, '
                f'{self._high[j] - POSITION_MARGIN_RAD:.4g}] rad plus {POSITION_MARGIN_RAD:g}'
            )
        rates = [('velocity', v, 'rad/s', self._velocity, VELOCITY_FACTOR)]
        if a is not None:
            rates.append(('acceleration', a, 'rad/s^2', self._acceleration, ACCELERATION_FACTOR))
        for name, values, unit, bound, factor in rates:
            beyond = np.abs(values) > bound
            if beyond.any():
                j = int(np.argmax(beyond))
                return (
                    f'{name} of {self.joints[j]} {values[j]:.6g} {unit} exceeds {factor:g} x '
                    'its limit'
                )
        return None


def check_finite(
    array: np.ndarray, joints: tuple[str, ...], stamps_ns: np.ndarray, where: str
) -> None:
    """Raise on the first NaN or Inf, naming the sample, its stamp and the joint.

    Raises:
        DatasetError: a value is NaN or infinite.
    """
    bad = ~np.isfinite(array)
    if bad.any():
        sample, column = (int(i) for i in np.argwhere(bad)[0])
        raise DatasetError(
            f'{where}: sample {sample} (stamp {int(stamps_ns[sample])} ns), '
            f'joint {joints[column]}: '
            f'value {array[sample, column]} is not finite ({int(bad.sum())} bad values in all)'
        )


def first_unpaired(a_ns: np.ndarray, b_ns: np.ndarray, period_s: float) -> int | None:
    """The first sample of the common length whose two stamps do not pair, or None.

    Stamps pair when they differ by at most ``PAIRING_SHARE`` of ``period_s`` [s].
    """
    size = min(len(a_ns), len(b_ns))
    apart = np.abs(np.asarray(a_ns[:size], dtype=np.int64) - np.asarray(b_ns[:size], np.int64))
    beyond = np.flatnonzero(apart > PAIRING_SHARE * period_s * 1e9)
    return int(beyond[0]) if beyond.size else None


def _two_streams(stamps_ns: np.ndarray) -> bool:
    """Stamps that go back more than once and are two increasing streams, taken in turn."""
    if np.count_nonzero(np.diff(stamps_ns) < 0) < 2:
        return False  # one step back: a clock step, or one sample out of place
    high = low = None  # the last stamps of the two streams, high >= low
    for stamp in np.asarray(stamps_ns).tolist():  # each on the stream it extends most closely
        if high is None or stamp > high:
            high = stamp
        elif low is None or stamp > low:
            low = stamp
        else:
            return False
    return True


def check_stamps(
    stamps_ns: np.ndarray, period_s: float, max_gap_periods: float, where: str
) -> None:
    """Require strictly increasing stamps without gaps longer than ``max_gap_periods`` periods.

    Raises:
        DatasetError: a stamp repeats or goes backwards, or a gap is too long (names the sample).
    """
    steps = np.diff(stamps_ns)
    if (steps <= 0).any():
        sample = int(np.argmax(steps <= 0)) + 1
        kind = 'repeats' if steps[sample - 1] == 0 else 'goes backwards'
        two = kind != 'repeats' and _two_streams(stamps_ns)
        raise DatasetError(
            f'{where}: time stamp {kind} at sample {sample}: {int(stamps_ns[sample - 1])} ns -> '
            f'{int(stamps_ns[sample])} ns'
            + ('; the stamps are two interleaved streams (two publishers?)' if two else '')
        )
    limit_ns = max_gap_periods * period_s * 1e9
    if (steps > limit_ns).any():
        sample = int(np.argmax(steps > limit_ns)) + 1
        raise DatasetError(
            f'{where}: gap of {steps[sample - 1] * 1e-6:.1f} ms before sample {sample} '
            f'(stamp {int(stamps_ns[sample])} ns) exceeds {max_gap_periods:g} IPO periods of '
            f'{period_s * 1e3:g} ms'
        )


def check_motion(
    joints: tuple[str, ...],
    stamps_ns: np.ndarray,
    q: np.ndarray,
    v: np.ndarray | None,
    *,
    limits: JointLimits | None,
    where: str,
) -> None:
    """Refuse motion no arm of these limits can have; see the module docstring.

    Args:
        joints: the columns' joint names, in the order of ``limits``.
        stamps_ns: (N,) sample stamps [ns].
        q: (N, n) positions [rad].
        v: (N, n) velocities [rad/s], or None.
        limits: the robot's joint limits, or None to check finiteness and stamps only.
        where: what the motion is (file and topic), for the message.

    Raises:
        DatasetError: the first violation, named as the module docstring says.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    for name, values in (('position', q), ('velocity', v)):
        if values is not None and np.shape(values) != (len(stamps), len(joints)):
            raise DatasetError(
                f'{where}: {name} has shape {np.shape(values)}, expected one value per joint '
                f'{list(joints)} for each of {len(stamps)} samples'
            )
    check_finite(np.asarray(q, float), joints, stamps, f'{where}: position')
    if v is not None:
        check_finite(np.asarray(v, float), joints, stamps, f'{where}: velocity')
    steps = np.diff(stamps)
    if (steps <= 0).any():
        sample = int(np.argmax(steps <= 0)) + 1
        raise DatasetError(
            f'{where}: stamps must increase: sample {sample} has {int(stamps[sample])} ns after '
            f'{int(stamps[sample - 1])} ns'
        )
    if limits is not None:
        check_limits(joints, stamps, q, v, limits=limits, where=where)


def check_limits(
    joints: tuple[str, ...],
    stamps_ns: np.ndarray,
    q: np.ndarray,
    v: np.ndarray | None,
    *,
    limits: JointLimits,
    where: str,
    urdf: Path | None = None,
) -> None:
    """The limit part of ``check_motion`` for finite values (positions, then velocities).

    Args:
        urdf: the robot's URDF: a position column that breaks the config's limits but fits the
            URDF's is named as a config question, not as degrees.

    Raises:
        DatasetError: the first position outside the limits plus the margin, or velocity beyond
            the factor, named as the module docstring says.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    _check_positions(joints, stamps, np.asarray(q, float), limits, where, urdf=urdf)
    if v is not None:
        _check_velocities(joints, stamps, np.asarray(v, float), limits, where)


def urdf_position_limits(urdf: Path, joint: str) -> tuple[float, float] | None:
    """The URDF's finite position limits [rad] of ``joint``, or None (none stated, unreadable)."""
    try:
        root = ElementTree.parse(urdf).getroot()
    except (OSError, ElementTree.ParseError):
        return None
    for element in root.iter('joint'):
        limit = element.find('limit')
        if element.get('name') != joint or limit is None:
            continue
        if element.get('type') not in ('revolute', 'prismatic'):
            return None
        try:
            lower, upper = float(limit.get('lower', 'nan')), float(limit.get('upper', 'nan'))
        except ValueError:
            return None
        if math.isfinite(lower) and math.isfinite(upper) and upper > lower:
            return lower, upper
    return None


def _fits(q: np.ndarray, lower: float, upper: float) -> bool:
    """Every value of q lies within [lower, upper] plus ``POSITION_MARGIN_RAD``."""
    return bool(((q >= lower - POSITION_MARGIN_RAD) & (q <= upper + POSITION_MARGIN_RAD)).all())


def _first(outside: np.ndarray) -> tuple[int, int]:
    sample, column = (int(i) for i in np.argwhere(outside)[0])
    return sample, column


def _check_positions(
    joints: tuple[str, ...],
    stamps: np.ndarray,
    q: np.ndarray,
    limits: JointLimits,
    where: str,
    *,
    urdf: Path | None = None,
) -> None:
    low = limits.position_lower - POSITION_MARGIN_RAD
    high = limits.position_upper + POSITION_MARGIN_RAD
    outside = (q < low) | (q > high)
    if not outside.any():
        return
    sample, column = _first(outside)
    value = q[sample, column]
    lower, upper = limits.position_lower[column], limits.position_upper[column]
    share, excess = beyond_position(value, lower, upper)
    farthest, _ = beyond_position(farthest_position(q[:, column], lower, upper), lower, upper)
    if farthest > share:
        excess += f'; the farthest sample of this joint lies {100 * farthest:.3g} % beyond'
    message = (
        f'{where}: sample {sample} (stamp {int(stamps[sample])} ns), joint {joints[column]}: '
        f'position {value:.6g} rad is outside the limits [{lower:.4g}, {upper:.4g}] rad plus '
        f'{POSITION_MARGIN_RAD:g} rad: {excess} ({int(outside[:, column].sum())} samples of this '
        'joint); '
    )
    reference = None if urdf is None else urdf_position_limits(urdf, joints[column])
    column_q = q[:, column]
    if reference is not None and _fits(column_q, *reference):
        raise DatasetError(
            f"{message}every value of this joint fits the URDF's limits [{reference[0]:.4g}, "
            f"{reference[1]:.4g}] rad ({urdf}): the robot config's limits are narrower than the "
            f"URDF's and than the recorded motion; correct limits.position_lower/position_upper "
            f'of {joints[column]} in the robot config (--robot)'
        )
    degrees = reads_as_degrees(column_q, lower, upper)
    remedy = 'the log is in degrees, positions must be in radians'
    raise DatasetError(message + beyond_hint(max(share, farthest), degrees, remedy))


def _check_velocities(
    joints: tuple[str, ...], stamps: np.ndarray, v: np.ndarray, limits: JointLimits, where: str
) -> None:
    _check_rate(joints, stamps, v, (limits.velocity, VELOCITY_FACTOR, 'velocity', 'rad/s'), where)


def _check_rate(
    joints: tuple[str, ...],
    stamps: np.ndarray,
    values: np.ndarray,
    bound: tuple[np.ndarray, float, str, str],
    where: str,
    *,
    derived: bool = False,
) -> None:
    """Refuse |values| beyond factor x limit; ``bound`` is (limit, factor, name, unit).

    What the values are is judged on the joint's worst sample, and on every joint: a column
    whose peak lies far beyond while read as degrees it fits is in degrees (``rate_in_degrees``).
    ``derived``: the values are differentiated from velocities that passed their own check, so
    their unit is right: too high a value is a limit or noise question.
    """
    limit, factor, name, unit = bound
    found = _beyond(values, factor * limit)
    if found is None:
        return
    sample, column, count = found
    value = values[sample, column]
    peak = float(np.max(np.abs(values[:, column])))
    share, excess = beyond_rate(value, limit[column], factor, unit)
    worst, _ = beyond_rate(peak, limit[column], factor, unit)
    if worst > share:
        excess += (
            f'; the largest |{name}| of this joint, {peak:.6g} {unit}, lies {100 * worst:.3g} % '
            'beyond'
        )
    beyond = np.abs(values) > factor * limit
    joints_beyond = [joints[j] for j in range(len(joints)) if beyond[:, j].any()]
    degrees = rate_in_degrees(values[:, column], factor * limit[column]) or rate_in_degrees(
        values, factor * limit
    )
    others = ''
    if len(joints_beyond) > 1:
        others = f'; {len(joints_beyond)} joints exceed ({", ".join(joints_beyond)})'
    degree_unit = unit.replace('rad', 'deg')
    plural = 'velocities' if name == 'velocity' else f'{name}s'
    hint = (
        f'differentiated from velocities within their limits: check limits.{name} in the robot '
        "config (--robot; if the arm's are wider, correct them there) and the velocities' noise"
        if derived
        else beyond_hint(
            max(share, worst),
            degrees,
            f'the {plural} are in {degree_unit}, they must be in {unit}',
            what=degree_unit,
        )
    )
    raise DatasetError(
        f'{where}: sample {sample} (stamp {int(stamps[sample])} ns), joint {joints[column]}: '
        f'{name} {value:.6g} {unit} exceeds {factor:g} x its limit: {excess} ({count} '
        f'samples of this joint){others}; {hint}'
    )


def rate_in_degrees(values: np.ndarray, bound: np.ndarray | float) -> bool:
    """Whether rate columns (velocities, accelerations) taken as radians are clearly in degrees.

    Read as degrees every finite value is within its ``bound`` (factor x its limit), and the
    largest peak |value| lies more than ``RATE_DEGREES_FACTOR`` x beyond its bound. (A column a
    few times its bound fits read as degrees too, but only as a motion at a few per cent of the
    limit.) ``values`` (N,) with a scalar bound, or (N, n) with (n,) bounds: the columns share
    their unit, so a slow joint is judged with the others.
    """
    values = np.abs(np.asarray(values, float))
    if values.size == 0:
        return False
    values = values.reshape(len(values), -1)
    bound = np.broadcast_to(np.asarray(bound, float), values.shape[1:])
    finite = np.where(np.isfinite(values), values, 0.0)
    peaks = finite.max(axis=0)
    if not (peaks / bound).max() > RATE_DEGREES_FACTOR:
        return False
    return bool((np.radians(peaks) <= bound).all())


def _beyond(values: np.ndarray, bound: np.ndarray) -> tuple[int, int, int] | None:
    """(sample, joint, samples of that joint) of the first |value| above its bound, or None."""
    beyond = np.abs(np.asarray(values, float)) > bound
    if not beyond.any():
        return None
    sample, column = _first(beyond)
    return sample, column, int(beyond[:, column].sum())


def check_efforts(
    joints: tuple[str, ...],
    stamps_ns: np.ndarray,
    torque: np.ndarray,
    *,
    torque_limit: np.ndarray,
    where: str,
    what: str = 'torque',
    unit_per_nm: np.ndarray | None = None,
) -> None:
    """Refuse torques (or currents) beyond ``TORQUE_FACTOR`` times the torque limits.

    Args:
        torque: (N, n) the values as recorded.
        torque_limit: (n,) the robot's joint-side torque limits [N*m].
        what: the quantity's name and unit for the message (e.g. 'current [A]').
        unit_per_nm: (n,) recorded units per N*m joint side (for currents
            ``1 / (gear_ratio * torque_constant)``); None for torques in N*m.

    Raises:
        DatasetError: the first value beyond the bound, naming sample, stamp, joint and value.
    """
    bound = effort_bound(torque_limit, unit_per_nm)
    needed = bound / TORQUE_FACTOR
    found = _beyond(torque, bound)
    if found is not None:
        sample, column, count = found
        peak = float(np.max(np.abs(torque[:, column]))) / bound[column]
        hint = ''
        if peak >= SCALE_PEAK_FACTOR:
            check = (
                'the unit and scale of the torques'
                if unit_per_nm is None
                else "the currents' unit (mA for A?) and the drives' gear_ratio and "
                'torque_constant'
            )
            hint = f'; its largest is {peak:.3g} x that bound, a unit question: check {check}'
        raise DatasetError(
            f'{where}: sample {sample} (stamp {int(stamps_ns[sample])} ns), joint '
            f'{joints[column]}: {what} {torque[sample, column]:.6g} exceeds {TORQUE_FACTOR:g} x '
            f'what the torque limit needs ({needed[column]:.4g}; {count} samples of this '
            f'joint){hint}'
        )


def effort_bound(torque_limit: np.ndarray, unit_per_nm: np.ndarray | None = None) -> np.ndarray:
    """(n,) the largest |torque| or |current| ``check_efforts`` lets pass, in recorded units.

    ``TORQUE_FACTOR`` x the torque limits [N*m], times ``unit_per_nm`` (for currents
    ``1 / (gear_ratio * torque_constant)``) when given.
    """
    needed = np.asarray(torque_limit, float)
    if unit_per_nm is not None:
        needed = needed * np.asarray(unit_per_nm, float)
    return TORQUE_FACTOR * needed


def check_accelerations(
    joints: tuple[str, ...],
    stamps_ns: np.ndarray,
    a: np.ndarray,
    *,
    limits: JointLimits,
    where: str,
) -> None:
    """Refuse accelerations beyond ``ACCELERATION_FACTOR`` times their limits (as SampleGate).

    The accelerations are differentiated from checked velocities: one too high is a limit (or
    noise) question, never a unit one.

    Raises:
        DatasetError: the first one, naming sample, stamp, joint and value.
    """
    bound = (limits.acceleration, ACCELERATION_FACTOR, 'acceleration', 'rad/s^2')
    _check_rate(joints, np.asarray(stamps_ns), a, bound, where, derived=True)
