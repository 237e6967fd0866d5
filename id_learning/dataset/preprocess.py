"""The reference study's preprocessing, from a recording to a training set.

1. motor currents to tau_u (or the measured joint torque, by choice of target);
2. zero-phase low-pass per joint with the robot's cut-offs (Butterworth, forward and backward);
3. accelerations by central differences of the filtered velocities;
4. a contiguous 70 % / 30 % train/test split (no shuffling: neighbouring samples are strongly
   correlated, so a shuffled split leaks);
5. per-joint normalisation to [-1, 1], with scalers fitted on the training part and kept.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Literal, Self

import numpy as np
from scipy import signal

from id_learning.dataset.recording import Recording
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import motor_torque_from_current

__all__ = [
    'Dataset',
    'MinMaxScaler',
    'PreprocessConfig',
    'Split',
    'differentiate',
    'lowpass',
    'minimum_duration_s',
    'prepare_dataset',
    'regularise',
]

_LOG = logging.getLogger(__name__)
Target = Literal['motor', 'joint']


@dataclass(frozen=True)
class PreprocessConfig:
    """Preprocessing settings.

    Attributes:
        target: 'motor' for tau_u from currents, 'joint' for measured joint torques.
        filter_order: Butterworth order of each pass (zero-phase doubles the attenuation).
        cutoff_hz: per-joint cut-offs [Hz]; None takes the robot config's lowpass_cutoff_hz.
        train_fraction: leading share of samples used for training.
        jitter_tolerance: a stamp within this share of a period from the IPO grid is on it.
        min_filter_periods: a recording must last this many periods of the lowest cut-off.
    """

    target: Target = 'motor'
    filter_order: int = 4
    cutoff_hz: tuple[float, ...] | None = None
    train_fraction: float = 0.7
    jitter_tolerance: float = 0.25
    min_filter_periods: float = 2.0

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if self.target not in ('motor', 'joint'):
            raise ConfigError(f"target must be 'motor' or 'joint', got {self.target!r}")
        if not 1 <= self.filter_order <= 8:
            raise ConfigError(f'filter_order must be in [1, 8], got {self.filter_order}')
        if not 0.0 < self.train_fraction < 1.0:
            raise ConfigError(f'train_fraction must be in (0, 1), got {self.train_fraction}')
        if not 0.0 < self.jitter_tolerance < 0.5:
            raise ConfigError(f'jitter_tolerance must be in (0, 0.5), got {self.jitter_tolerance}')


def minimum_duration_s(cutoff_hz: np.ndarray, config: PreprocessConfig) -> float:
    """Shortest recording the filter accepts [s]: min_filter_periods of the lowest cut-off."""
    return config.min_filter_periods / float(np.min(cutoff_hz))


def lowpass(x: np.ndarray, cutoff_hz: np.ndarray, period_s: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of each column of x (N, n) with its own cut-off [Hz].

    Raises:
        DatasetError: too few samples for the filter's padding.
    """
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    for j in range(x.shape[1]):
        sos = signal.butter(order, cutoff_hz[j], btype='low', fs=1.0 / period_s, output='sos')
        try:
            out[:, j] = signal.sosfiltfilt(sos, x[:, j])
        except ValueError as err:
            raise DatasetError(
                f'{len(x)} samples are too few for the {cutoff_hz[j]:g} Hz low-pass '
                f'of column {j}: {err}'
            ) from err
    return out


def differentiate(x: np.ndarray, period_s: float) -> np.ndarray:
    """Time derivative of uniformly sampled columns by central differences (second-order edges)."""
    return np.gradient(np.asarray(x, dtype=float), period_s, axis=0, edge_order=2)


@dataclass
class MinMaxScaler:
    """Per-column affine map of [min, max] onto [-1, 1] (the study's normalisation).

    Follows the estimator contract: fit() returns self, fitted state ends in ``_``.
    """

    low_: np.ndarray | None = None
    high_: np.ndarray | None = None

    def fit(self, x: np.ndarray) -> Self:
        """Learn each column's range; a constant column maps to 0."""
        self.low_ = np.min(x, axis=0)
        self.high_ = np.max(x, axis=0)
        return self

    def _centre_half_range(self) -> tuple[np.ndarray, np.ndarray]:
        if self.low_ is None or self.high_ is None:
            raise RuntimeError('MinMaxScaler is not fitted')
        half = 0.5 * (self.high_ - self.low_)
        return 0.5 * (self.high_ + self.low_), np.where(half > 0, half, 1.0)

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Map to the normalised scale."""
        centre, half = self._centre_half_range()
        return (x - centre) / half

    def inverse_transform(self, z: np.ndarray) -> np.ndarray:
        """Map back to physical units."""
        centre, half = self._centre_half_range()
        return z * half + centre

    def scale(self) -> np.ndarray:
        """Half ranges: an error e in physical units is e / half on the normalised scale."""
        return self._centre_half_range()[1]

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-ready state."""
        centre, half = self._centre_half_range()
        del centre, half
        assert self.low_ is not None
        assert self.high_ is not None
        return {'low': self.low_.tolist(), 'high': self.high_.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MinMaxScaler:
        """Rebuild a fitted scaler from ``to_dict`` output."""
        return cls(np.asarray(data['low'], dtype=float), np.asarray(data['high'], dtype=float))


@dataclass(frozen=True, eq=False)
class RegulariseReport:
    """What regularise() changed: nothing is altered silently."""

    n_snapped: int
    max_jitter_s: float
    filled_samples: tuple[int, ...]

    def summary(self) -> str:
        """One line for logs and reports."""
        return (
            f'{self.n_snapped} stamps snapped to the IPO grid '
            f'(max jitter {self.max_jitter_s * 1e3:.3f} ms), '
            f'{len(self.filled_samples)} missing samples interpolated'
        )


def regularise(
    recording: Recording, period_s: float, jitter_tolerance: float = 0.25
) -> tuple[Recording, RegulariseReport]:
    """Put the samples on the uniform IPO grid the filter assumes.

    Stamps within ``jitter_tolerance`` periods of the grid are snapped onto it; grid slots with no
    sample (short gaps; long ones were refused when loading) are filled by linear interpolation
    and listed in the report.

    Raises:
        DatasetError: a stamp is further from the grid than the tolerance, or two share a slot.
    """
    period_ns = period_s * 1e9
    offsets = (recording.stamps_ns - recording.stamps_ns[0]).astype(float)
    slots = np.round(offsets / period_ns).astype(np.int64)
    jitter = np.abs(offsets - slots * period_ns)
    if (jitter > jitter_tolerance * period_ns).any():
        sample = int(np.argmax(jitter > jitter_tolerance * period_ns))
        raise DatasetError(
            f'{recording.source}: sample {sample} '
            f'(stamp {int(recording.stamps_ns[sample])} ns) is '
            f'{jitter[sample] * 1e-6:.3f} ms off the {period_s * 1e3:g} ms IPO grid (tolerance '
            f'{jitter_tolerance * period_s * 1e3:.3f} ms); resample the log first'
        )
    if (np.diff(slots) == 0).any():
        sample = int(np.argmax(np.diff(slots) == 0)) + 1
        raise DatasetError(
            f'{recording.source}: samples {sample - 1} and {sample} fall on the same IPO slot'
        )
    n_slots = int(slots[-1]) + 1
    grid_ns = recording.stamps_ns[0] + np.round(np.arange(n_slots) * period_ns).astype(np.int64)
    filled = np.setdiff1d(np.arange(n_slots), slots)
    report = RegulariseReport(
        int(np.count_nonzero(jitter > 0)), float(jitter.max() * 1e-9), tuple(filled.tolist())
    )
    if not filled.size and not report.n_snapped:
        return recording, report

    def on_grid(array: np.ndarray | None) -> np.ndarray | None:
        if array is None:
            return None
        out = np.empty((n_slots, array.shape[1]))
        for j in range(array.shape[1]):
            out[:, j] = np.interp(np.arange(n_slots), slots, array[:, j])
        return out

    regular = Recording(
        joints=recording.joints,
        stamps_ns=grid_ns,
        position=on_grid(recording.position),
        velocity=on_grid(recording.velocity),
        current=on_grid(recording.current),
        joint_torque=on_grid(recording.joint_torque),
        source=recording.source,
    )
    _LOG.info('%s: %s', recording.source, report.summary())
    return regular, report


@dataclass(frozen=True, eq=False)
class Split:
    """One part of a dataset; arrays (N, n) in SI units, joint side."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    stamps_ns: np.ndarray

    @property
    def inputs(self) -> np.ndarray:
        """(N, 3n) model inputs [q, v, a]."""
        return np.hstack([self.q, self.v, self.a])


@dataclass(frozen=True, eq=False)
class Dataset:
    """A preprocessed recording, split in time, with scalers fitted on the training part.

    Attributes:
        joints: joint names (column order).
        target: 'motor' (tau_u from currents) or 'joint' (measured joint torque).
        period_s: sample period [s].
        stamps_ns: (N,) stamps on the IPO grid.
        q, v, a, tau: (N, n) filtered positions, velocities, accelerations, target torques.
        tau_raw: (N, n) target torque before filtering.
        n_train: the first n_train samples are the training part, the rest the test part.
        input_scaler, target_scaler: fitted on the training part.
        cutoff_hz: per-joint cut-offs used [Hz]; filter_order: Butterworth order.
        regularise_report: what regularise() changed.
    """

    joints: tuple[str, ...]
    target: Target
    period_s: float
    stamps_ns: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    tau_raw: np.ndarray
    n_train: int
    input_scaler: MinMaxScaler
    target_scaler: MinMaxScaler
    cutoff_hz: np.ndarray
    filter_order: int
    regularise_report: RegulariseReport | None = None
    source: str = ''
    extra: dict[str, Any] = field(default_factory=dict)

    def _part(self, rows: slice) -> Split:
        return Split(
            self.q[rows], self.v[rows], self.a[rows], self.tau[rows], self.stamps_ns[rows]
        )

    @property
    def train(self) -> Split:
        """The leading, contiguous training part."""
        return self._part(slice(0, self.n_train))

    @property
    def test(self) -> Split:
        """The trailing, contiguous test part."""
        return self._part(slice(self.n_train, None))


def target_torque(recording: Recording, robot: RobotConfig, target: Target) -> np.ndarray:
    """The label torque [N*m] before filtering: tau_u from currents, or measured joint torque.

    Raises:
        DatasetError: the recording lacks what the target needs.
    """
    if target == 'motor':
        if recording.current is None:
            raise DatasetError(f'{recording.source}: no motor currents, so no motor torque target')
        return motor_torque_from_current(recording.current, robot.drives)
    if recording.joint_torque is None:
        raise DatasetError(
            f'{recording.source}: {robot.topics.joint_states} carries no effort (joint torques); '
            "use the 'motor' target (tau_u from currents)"
        )
    return recording.joint_torque


def prepare_dataset(
    recording: Recording, robot: RobotConfig, config: PreprocessConfig | None = None
) -> Dataset:
    """Run the study's preprocessing on one recording.

    Raises:
        DatasetError: the recording is too short for the filter, lacks the target, or is off-grid.
    """
    config = config or PreprocessConfig()
    cutoff = np.asarray(
        config.cutoff_hz if config.cutoff_hz is not None else robot.lowpass_cutoff_hz
    )
    if cutoff.shape != (robot.n_joints,):
        raise ConfigError(f'cutoff_hz needs {robot.n_joints} values, got {cutoff.tolist()}')
    needed = minimum_duration_s(cutoff, config)
    if recording.duration_s < needed:
        slowest = robot.joints[int(np.argmin(cutoff))]
        raise DatasetError(
            f'{recording.source}: {recording.duration_s:.1f} s of data '
            'is too short for the filter: '
            f'at least {needed:.1f} s are needed for the {cutoff.min():g} Hz cut-off of {slowest}'
        )
    regular, report = regularise(recording, robot.ipo_period_s, config.jitter_tolerance)
    tau_raw = target_torque(regular, robot, config.target)
    period = robot.ipo_period_s
    q = lowpass(regular.position, cutoff, period, config.filter_order)
    v = lowpass(regular.velocity, cutoff, period, config.filter_order)
    tau = lowpass(tau_raw, cutoff, period, config.filter_order)
    a = differentiate(v, period)
    n_train = round(config.train_fraction * len(q))
    inputs = np.hstack([q, v, a])
    return Dataset(
        joints=robot.joints,
        target=config.target,
        period_s=period,
        stamps_ns=regular.stamps_ns,
        q=q,
        v=v,
        a=a,
        tau=tau,
        tau_raw=tau_raw,
        n_train=n_train,
        input_scaler=MinMaxScaler().fit(inputs[:n_train]),
        target_scaler=MinMaxScaler().fit(tau[:n_train]),
        cutoff_hz=cutoff,
        filter_order=config.filter_order,
        regularise_report=report,
        source=recording.source,
    )
