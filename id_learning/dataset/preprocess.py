"""From a recording to a training set: labels through the study's filter, inputs as sent.

1. motor currents to tau_u (or the measured joint torque, by choice of target);
2. the labels: zero-phase low-pass per joint with the robot's cut-offs (Butterworth, forward and
   backward), as the reference study does;
3. the inputs (``dataset.inputs``): by default what a controller sends (recorded positions,
   velocities smoothed far above the motion's band, accelerations differentiated from them);
   with ``mode='study'`` the study's inputs (positions and velocities low-passed like the
   labels). Both are kept, so any model can be scored on either;
4. a contiguous 70 % / 30 % train/test split (no shuffling: neighbouring samples are strongly
   correlated, so a shuffled split leaks);
5. per-joint normalisation to [-1, 1], with scalers fitted on the training part and kept.

Why not the study's way by default: friction flips sign at every velocity reversal, and the
0.3-1.2 Hz filter smears each flip over 1-2 s, so the filtered label is not a function of the
filtered state at the same instant; no instantaneous model can match it. Models are therefore
fitted *through* the filter (``mode='through_filter'``): their torque on the unfiltered inputs
passes the labels' filter before it meets the label (parallel filtering, Gautier and Khalil).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Literal, Self

import numpy as np

from id_learning.config_io import finite_number
from id_learning.dataset.inputs import InputDefinition, Motion
from id_learning.dataset.recording import Recording
from id_learning.dataset.sampling_grid import SAMPLING_TOLERANCE, grid_slots, sampling_problem
from id_learning.dataset.signals import differentiate, lowpass
from id_learning.errors import ConfigError, DatasetError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import motor_torque_from_current

__all__ = [
    'PREPROCESS_MODES',
    'SPLITS',
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
PreprocessMode = Literal['through_filter', 'study']
#: 'through_filter': fit on a controller's inputs, model torque filtered like the labels;
#: 'study': the reference study's pipeline, filtered inputs to filtered labels, instantaneous.
PREPROCESS_MODES: tuple[PreprocessMode, ...] = ('through_filter', 'study')
SplitKind = Literal['contiguous', 'shuffled']
#: 'contiguous': the leading train_fraction of each recording in time trains, the rest tests;
#: 'shuffled': train_fraction of the samples, drawn at random, train (the study's wording allows
#: either); the recordings stay whole in time, so filters and windows still run along them.
SPLITS: tuple[SplitKind, ...] = ('contiguous', 'shuffled')


@dataclass(frozen=True)
class PreprocessConfig:
    """Preprocessing settings.

    Attributes:
        target: 'motor' for tau_u from currents, 'joint' for measured joint torques.
        mode: 'through_filter' (models see a controller's inputs and are fitted and judged
            with their torque passed through the labels' filter) or 'study' (the reference
            study's pipeline: filtered inputs, torque compared with the filtered label as is).
        filter_order: Butterworth order of each pass (zero-phase doubles the attenuation).
        cutoff_hz: per-joint cut-offs [Hz]; None takes the robot config's lowpass_cutoff_hz.
        input_smoothing_hz: per-joint cut-offs of the controller inputs' velocity smoothing
            [Hz]; None takes the robot config's input_smoothing_hz (a stored model's own
            definition when it is evaluated).
        train_fraction: share of samples used for training (the leading ones in time, or drawn
            at random: ``split``).
        split: 'contiguous' (default) or 'shuffled' (``SPLITS``).
        split_seed: seeds the draw of a shuffled split (and of its validation samples).
        jitter_tolerance: a stamp within this share of a period from the IPO grid is on it.
        min_filter_periods: a recording must last this many periods of the lowest cut-off.
    """

    target: Target = 'motor'
    mode: PreprocessMode = 'through_filter'
    filter_order: int = 4
    cutoff_hz: tuple[float, ...] | None = None
    input_smoothing_hz: tuple[float, ...] | None = None
    train_fraction: float = 0.7
    jitter_tolerance: float = SAMPLING_TOLERANCE
    min_filter_periods: float = 2.0
    split: SplitKind = 'contiguous'
    split_seed: int = 0

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if self.target not in ('motor', 'joint'):
            raise ConfigError(f"target must be 'motor' or 'joint', got {self.target!r}")
        if self.mode not in PREPROCESS_MODES:
            raise ConfigError(
                f'preprocessing mode must be one of {PREPROCESS_MODES}, got {self.mode!r}'
            )
        if not 1 <= self.filter_order <= 8:
            raise ConfigError(f'filter_order must be in [1, 8], got {self.filter_order}')
        if not 0.0 < self.train_fraction < 1.0:
            raise ConfigError(f'train_fraction must be in (0, 1), got {self.train_fraction}')
        if not 0.0 < self.jitter_tolerance < 0.5:
            raise ConfigError(f'jitter_tolerance must be in (0, 0.5), got {self.jitter_tolerance}')
        if self.split not in SPLITS:
            raise ConfigError(f'split must be one of {SPLITS}, got {self.split!r}')
        if not isinstance(self.split_seed, int) or self.split_seed < 0:
            raise ConfigError(f'split_seed must be an integer >= 0, got {self.split_seed!r}')
        finite_number(self.min_filter_periods, 'min_filter_periods', low=0.0, low_open=True)
        for key in ('cutoff_hz', 'input_smoothing_hz'):
            values = getattr(self, key)
            for index, value in enumerate(values if values is not None else ()):
                finite_number(value, f'{key}[{index}] [Hz]', low=0.0, low_open=True)


def minimum_duration_s(cutoff_hz: np.ndarray, config: PreprocessConfig) -> float:
    """Shortest recording the filter accepts [s]: min_filter_periods of the lowest cut-off."""
    return config.min_filter_periods / float(np.min(cutoff_hz))


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
        out: np.ndarray = (x - centre) / half
        return out

    def inverse_transform(self, z: np.ndarray) -> np.ndarray:
        """Map back to physical units."""
        centre, half = self._centre_half_range()
        out: np.ndarray = z * half + centre
        return out

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
    recording: Recording, period_s: float, jitter_tolerance: float = SAMPLING_TOLERANCE
) -> tuple[Recording, RegulariseReport]:
    """Put the samples on the uniform IPO grid the filter assumes.

    Stamps within ``jitter_tolerance`` periods of the grid are snapped onto it; grid slots with no
    sample (short gaps; long ones were refused when loading) are filled by linear interpolation
    and listed in the report.

    Raises:
        DatasetError: the log is sampled at another period than ``period_s`` (the robot
            config's; ``sampling_grid.sampling_problem`` names both), a stamp is further from
            the grid than the tolerance, or two share a slot.
    """
    period_ns = period_s * 1e9
    slots, jitter = grid_slots(recording.stamps_ns, period_ns, recording.stamps_ns[0])
    if (jitter > jitter_tolerance * period_ns).any():
        steps = np.diff(recording.stamps_ns)
        own = float(np.median(steps[steps > 0])) if (steps > 0).any() else period_ns
        line = sampling_problem(recording.stamps_ns, period_s, str(recording.source))
        if line is not None and abs(own / period_ns - 1.0) > jitter_tolerance:
            raise DatasetError(line)  # the whole log is at another period, not one sample off
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

    def resampled(array: np.ndarray) -> np.ndarray:
        out = np.empty((n_slots, array.shape[1]))
        for j in range(array.shape[1]):
            out[:, j] = np.interp(np.arange(n_slots), slots, array[:, j])
        return out

    def on_grid(array: np.ndarray | None) -> np.ndarray | None:
        return None if array is None else resampled(array)

    regular = Recording(
        joints=recording.joints,
        stamps_ns=grid_ns,
        position=resampled(recording.position),
        velocity=resampled(recording.velocity),
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
    """A preprocessed recording (or several), split in time, with scalers from the training part.

    Attributes:
        joints: joint names (column order).
        target: 'motor' (tau_u from currents) or 'joint' (measured joint torque).
        period_s: sample period [s].
        stamps_ns: (N,) stamps on the IPO grid.
        q, v, a: (N, n) the inputs models are fitted on: ``controller`` in the default mode,
            ``study`` in the study's (see ``fitting_inputs``).
        tau: (N, n) label torques, low-passed with ``cutoff_hz`` (the label filter).
        tau_raw: (N, n) label torques before filtering.
        n_train: the number of training samples: the first n_train (contiguous split) or those
            ``train_mask`` marks (shuffled).
        input_scaler, target_scaler: fitted on the training part (of q, v, a and of tau).
        cutoff_hz: per-joint cut-offs of the label filter [Hz]; filter_order: its order.
        mode: 'through_filter' or 'study' (``PreprocessConfig.mode``).
        controller: (N, n) each, the inputs a controller sends (``controller_inputs``): what
            every model is scored on and what the predictor receives online.
        study: (N, n) each, the study's inputs: q and v low-passed like the labels.
        controller_inputs: how ``controller`` was made.
        tau_clean: (N, n) the noise-free label torque before filtering [N*m], where known (a
            twin recording's ground truth); None otherwise.
        regularise_report: what regularise() changed.
        extra: 'segments' when several recordings are combined (see ``recording_rows``).
        train_mask: (N,) True for the training samples of a shuffled split; None: contiguous.
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
    mode: PreprocessMode
    controller: Motion
    study: Motion
    controller_inputs: InputDefinition
    tau_clean: np.ndarray | None = None
    regularise_report: RegulariseReport | None = None
    source: str = ''
    extra: dict[str, Any] = field(default_factory=dict)
    train_mask: np.ndarray | None = None

    def _part(self, rows: np.ndarray) -> Split:
        return Split(
            self.q[rows], self.v[rows], self.a[rows], self.tau[rows], self.stamps_ns[rows]
        )

    @property
    def is_shuffled(self) -> bool:
        """The split drew its training samples at random (``train_mask``)."""
        return self.train_mask is not None

    @property
    def train_rows(self) -> np.ndarray:
        """Rows of the training samples, in row order."""
        if self.train_mask is not None:
            return np.flatnonzero(self.train_mask)
        return np.arange(self.n_train)

    @property
    def test_rows(self) -> np.ndarray:
        """Rows of the test samples, in row order (each recording's test range, combined)."""
        if self.train_mask is not None:
            return np.flatnonzero(~self.train_mask)
        segments = self.extra.get('segments')
        if segments and all('test' in s for s in segments):
            return np.concatenate([np.arange(*s['test']) for s in segments])
        return np.arange(self.n_train, len(self.tau))

    @property
    def train(self) -> Split:
        """The training samples."""
        return self._part(self.train_rows)

    @property
    def test(self) -> Split:
        """The test samples."""
        return self._part(self.test_rows)

    @property
    def is_through_filter(self) -> bool:
        """Models are fitted with their torque passed through the label filter."""
        return self.mode == 'through_filter'

    @property
    def fitting_inputs(self) -> InputDefinition:
        """How q, v and a (the inputs models are fitted on) were made."""
        if self.is_through_filter:
            return self.controller_inputs
        return InputDefinition.study(self.cutoff_hz, self.filter_order)

    @property
    def label_filter(self) -> dict[str, Any]:
        """The label filter, JSON-ready."""
        return {
            'filter': 'zero-phase Butterworth low-pass (scipy sosfiltfilt)',
            'cutoff_hz': np.asarray(self.cutoff_hz, dtype=float).tolist(),
            'filter_order': self.filter_order,
        }

    def recording_rows(self) -> list[np.ndarray]:
        """Per recording, its rows in time order (training part, then test part)."""
        segments = self.extra.get('segments')
        if not segments:
            return [np.arange(len(self.q))]
        return [
            np.arange(*s['rows'])
            if 'rows' in s
            else np.concatenate([np.arange(*s['train']), np.arange(*s['test'])])
            for s in segments
        ]

    def filter_like_labels(self, x: np.ndarray, joint: int | None = None) -> np.ndarray:
        """Low-pass x (N, n, rows in order) exactly like the labels, each recording on its own.

        The label filter is zero-phase over a whole recording, so a model's torque (or a
        regressor column) along the recording becomes comparable with ``tau`` sample by sample.
        With ``joint``, x is (N, k): k columns that all belong to that joint's label.
        """
        x = np.asarray(x, dtype=float)
        cutoff = self.cutoff_hz if joint is None else np.full(x.shape[1], self.cutoff_hz[joint])
        out = np.empty_like(x)
        for rows in self.recording_rows():
            out[rows] = lowpass(x[rows], cutoff, self.period_s, self.filter_order)
        return out


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
            f'{recording.source}: {robot.topics.joint_states} carries no effort (joint torques), '
            "which the 'joint' target needs: a model trained on measured joint torques is "
            "evaluated on recordings that hold them; tau_u from currents is the 'motor' target"
        )
    return recording.joint_torque


def _below_nyquist(cutoff_hz: np.ndarray, key: str, robot: RobotConfig) -> None:
    """Refuse a cut-off at or above the Nyquist frequency of the robot's IPO period.

    A digital low-pass cannot cut at or above half the sample rate (scipy refuses its design).

    Raises:
        ConfigError: names the key, the joint, the cut-off, the Nyquist frequency and the period.
    """
    nyquist = 0.5 / robot.ipo_period_s
    above = np.flatnonzero(~(np.asarray(cutoff_hz, dtype=float) < nyquist))
    if above.size:
        joint = int(above[0])
        raise ConfigError(
            f'{key}: {float(cutoff_hz[joint]):g} Hz for {robot.joints[joint]} is at or above '
            f'the Nyquist frequency {nyquist:g} Hz of the {robot.ipo_period_s * 1e3:g} ms IPO '
            'period (ipo_period_s); give a cut-off below it'
        )


def prepare_dataset(
    recording: Recording,
    robot: RobotConfig,
    config: PreprocessConfig | None = None,
    *,
    segment: int = 0,
) -> Dataset:
    """Preprocess one recording: labels through the study's filter, inputs both ways.

    ``segment``: the recording's index among a bag's segments; a shuffled split draws each
    segment's samples from its own random stream (the first one's is the split seed's).

    Raises:
        DatasetError: the recording is too short for the filter, lacks the target, or is off-grid.
    """
    config = config or PreprocessConfig()
    if len(recording.segment_starts) > 1:
        raise DatasetError(
            f'{recording.source}: holds {len(recording.segment_starts)} segments; prepare each '
            '(Recording.segments()) and combine them (training.combine_datasets)'
        )
    cutoff = np.asarray(
        config.cutoff_hz if config.cutoff_hz is not None else robot.lowpass_cutoff_hz
    )
    if cutoff.shape != (robot.n_joints,):
        raise ConfigError(f'cutoff_hz needs {robot.n_joints} values, got {cutoff.tolist()}')
    _below_nyquist(cutoff, 'cutoff_hz', robot)
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
    smoothing = np.asarray(
        config.input_smoothing_hz
        if config.input_smoothing_hz is not None
        else robot.input_smoothing_hz
    )
    if smoothing.shape != (robot.n_joints,):
        raise ConfigError(
            f'input_smoothing_hz needs {robot.n_joints} values, got {smoothing.tolist()}'
        )
    _below_nyquist(smoothing, 'input_smoothing_hz', robot)
    controller_inputs = InputDefinition.controller(smoothing, config.filter_order)
    controller = controller_inputs.motion(regular.position, regular.velocity, period)
    study = InputDefinition.study(cutoff, config.filter_order).motion(
        regular.position, regular.velocity, period
    )
    fitting = controller if config.mode == 'through_filter' else study
    tau = lowpass(tau_raw, cutoff, period, config.filter_order)
    n_train = round(config.train_fraction * len(tau))
    mask = (
        shuffled_mask(len(tau), n_train, config.split_seed, segment)
        if config.split == 'shuffled'
        else None
    )
    fit = np.flatnonzero(mask) if mask is not None else slice(0, n_train)
    inputs = np.hstack([fitting.q, fitting.v, fitting.a])
    return Dataset(
        joints=robot.joints,
        target=config.target,
        period_s=period,
        stamps_ns=regular.stamps_ns,
        q=fitting.q,
        v=fitting.v,
        a=fitting.a,
        tau=tau,
        tau_raw=tau_raw,
        n_train=n_train,
        input_scaler=MinMaxScaler().fit(inputs[fit]),
        target_scaler=MinMaxScaler().fit(tau[fit]),
        cutoff_hz=cutoff,
        filter_order=config.filter_order,
        mode=config.mode,
        controller=controller,
        study=study,
        controller_inputs=controller_inputs,
        regularise_report=report,
        source=recording.source,
        train_mask=mask,
    )


def shuffled_mask(n_samples: int, n_train: int, seed: int, segment: int = 0) -> np.ndarray:
    """(n_samples,) True for n_train samples drawn at random (seeded): a shuffled split.

    Segments after a bag's first draw from streams of their own, so that two segments of one
    length do not share a mask.
    """
    rng = np.random.default_rng(seed if segment == 0 else [seed, segment])
    mask = np.zeros(n_samples, dtype=bool)
    mask[rng.permutation(n_samples)[:n_train]] = True
    return mask
