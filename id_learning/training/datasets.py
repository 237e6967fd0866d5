"""Loading the bags of a run: preprocessing each on its own, hashing, and joining them.

Several bags, or several segments of one bag: each is preprocessed on its own (the zero-phase
filter and the differentiation must not run across the seam of two recordings) and split 70/30
in time on its own; the training
parts are concatenated in bag order, then the test parts (``combine_datasets``). For evaluating a
run on other recordings they are joined whole instead (``concatenate_for_evaluation``). Kept apart
from fitting and the run folder because the online check and the benchmarks load data the same
way without training anything.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from id_learning.bag.distinct import (
    MIN_SHARED_SAMPLES,
    Samples,
    refuse_shared_samples,
    shared_samples,
    shared_stamps,
)
from id_learning.dataset.content import GravityTorque, gravity_findings
from id_learning.dataset.inputs import InputDefinition, Motion
from id_learning.dataset.preprocess import Dataset, MinMaxScaler, PreprocessConfig, prepare_dataset
from id_learning.dataset.recording import Recording, load_recording
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.models.data import TrainingData
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig
from id_learning.training.shared_segments import refuse_shared_segments
from id_learning.twin import read_noise_free_torque
from id_learning.twin.needed_torque import (
    NEEDED_TORQUE,
    NEEDED_TORQUE_NOTES,
    join_needed_torque,
    needed_torque,
)

__all__ = [
    'DATA_WARNINGS',
    'GROUND_TRUTH_NOTES',
    'MIN_SHARED_SAMPLES',
    'Samples',
    'bag_of',
    'bag_sha256',
    'combine_datasets',
    'concatenate_for_evaluation',
    'data_sha256',
    'data_warnings',
    'datasets_by_bag',
    'load_datasets',
    'mask_sha256',
    'preprocess_from_dict',
    'preprocess_to_dict',
    'refuse_shared_samples',
    'seen_rows',
    'segment_rows',
    'shared_samples',
    'shared_stamps',
    'training_data_summary',
]

_LOG = logging.getLogger(__name__)


def bag_sha256(path: Path) -> str:
    """SHA-256 over a bag's bytes: metadata.yaml and its storage files, in name order.

    Files the twin adds beside the bag (ground truth, its config copy) are not part of the data.
    """
    path = Path(path)
    if path.is_file():
        files = [path]
    else:
        files = sorted(
            p
            for p in path.iterdir()
            if p.is_file() and (p.name == 'metadata.yaml' or p.suffix in ('.mcap', '.db3'))
        )
    if not files:
        raise DatasetError(f'{path}: no bag files (metadata.yaml, *.mcap, *.db3) to hash')
    digest = hashlib.sha256()
    for file in files:
        digest.update(file.name.encode())
        with file.open('rb') as stream:
            for block in iter(lambda: stream.read(1 << 20), b''):
                digest.update(block)
    return digest.hexdigest()


def data_sha256(dataset: Dataset) -> str:
    """SHA-256 of the preprocessed arrays a model sees (q, v, a, tau as float64) and the split."""
    digest = hashlib.sha256()
    for array in (dataset.q, dataset.v, dataset.a, dataset.tau):
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    digest.update(str(dataset.n_train).encode())
    if dataset.train_mask is not None:
        digest.update(np.packbits(dataset.train_mask).tobytes())
    return digest.hexdigest()


def preprocess_to_dict(config: PreprocessConfig, dataset: Dataset) -> dict[str, Any]:
    """The preprocessing settings as used (cut-offs and inputs resolved), JSON-ready.

    ``inputs`` is the input definition a model is scored and served on (a controller's);
    ``fitting_inputs`` the one it was fitted on (the same, or the study's filtered inputs).
    """
    return {
        'target': config.target,
        'mode': config.mode,
        'filter': 'zero-phase Butterworth low-pass (scipy sosfiltfilt)',
        'filter_order': config.filter_order,
        'cutoff_hz': np.asarray(dataset.cutoff_hz, dtype=float).tolist(),
        'train_fraction': config.train_fraction,
        'split': config.split,
        'split_seed': config.split_seed,
        'jitter_tolerance': config.jitter_tolerance,
        'min_filter_periods': config.min_filter_periods,
        'inputs': dataset.controller_inputs.to_dict(),
        'fitting_inputs': dataset.fitting_inputs.to_dict(),
    }


def preprocess_from_dict(data: dict[str, Any]) -> PreprocessConfig:
    """Rebuild the PreprocessConfig of a run from ``preprocess_to_dict`` output."""
    try:
        inputs = data.get('inputs')
        return PreprocessConfig(
            target=data['target'],
            # Runs written before the mode existed were fitted the study's way.
            mode=data.get('mode', 'study'),
            filter_order=int(data['filter_order']),
            cutoff_hz=tuple(float(x) for x in data['cutoff_hz']),
            input_smoothing_hz=None
            if inputs is None
            else InputDefinition.from_dict(inputs).velocity_cutoff_hz,
            train_fraction=float(data['train_fraction']),
            # Runs written before the split could be chosen were split in time.
            split=data.get('split', 'contiguous'),
            split_seed=int(data.get('split_seed', 0)),
            jitter_tolerance=float(data['jitter_tolerance']),
            min_filter_periods=float(data['min_filter_periods']),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f'preprocessing settings are incomplete or invalid: {err}') from err


def load_datasets(
    bags: Sequence[Path],
    robot: RobotConfig,
    config: PreprocessConfig,
    *,
    progress: bool = True,
    trim_unpaired_tail: bool = False,
) -> list[Dataset]:
    """Load and preprocess each bag on its own (filtering never crosses two recordings).

    ``trim_unpaired_tail``: drop a torn recording's last unpaired messages (``load_recording``).
    """
    if not bags:
        raise ConfigError('no bag given: pass at least one --bag')
    datasets = []
    samples: list[Samples] = []
    gravity = RigidBodyDynamics.from_config(robot).gravity  # one model for every bag
    for bag in tqdm(bags, desc='loading bags', unit='bag', disable=not progress or len(bags) < 2):
        recording = load_recording(
            Path(bag),
            robot,
            require_current=config.target == 'motor',
            progress=progress,
            trim_unpaired_tail=trim_unpaired_tail,
            gravity=gravity,
        )
        refuse_shared_segments(samples, Path(bag), recording)  # before the work of preprocessing
        # What load_recording warned of (a still joint, a clipped label), for the report too.
        nominal = _nominal_findings(recording, robot, config.target, gravity)
        for text in nominal:  # load_recording logged the others
            _LOG.warning('%s: %s', bag, text)
        warnings = [f'{bag}: {text}' for text in (*recording.content_warnings, *nominal)]
        for k, segment in enumerate(recording.segments()):
            try:
                dataset = prepare_dataset(segment, robot, config, segment=k)
            except DatasetError as err:
                if len(recording.segment_starts) == 1:
                    raise
                raise DatasetError(
                    f'{err}; every segment of a bag is preprocessed on its own: re-import with '
                    'resample.min_segment_s to drop short segments (reported), or a larger '
                    'resample.max_gap_s to keep them joined'
                ) from err
            clean, ignored = read_noise_free_torque(bag, dataset)
            if ignored and ignored not in warnings:
                _LOG.warning('%s', ignored)
                warnings.append(ignored)
            extra = {**dataset.extra, 'bag': str(bag), DATA_WARNINGS: warnings}
            if ignored:
                extra[GROUND_TRUTH_NOTES] = [ignored]
            extra |= _needed_torque_extra(bag, dataset) if clean is not None else {}
            datasets.append(replace(dataset, tau_clean=clean, extra=extra))
        _LOG.info(
            '%s: %d samples in %d segment(s)',
            bag,
            recording.n_samples,
            len(recording.segment_starts),
        )
    return _note_partial_ground_truth(datasets)


def _needed_torque_extra(bag: Path, dataset: Dataset) -> dict[str, Any]:
    """The ``Dataset.extra`` entries of a twin bag's needed torque, or of why there is none."""
    needed, why = needed_torque(bag, dataset)
    if why:
        _LOG.warning('%s', why)
        return {NEEDED_TORQUE_NOTES: [why]}
    return {} if needed is None else {NEEDED_TORQUE: needed}


#: ``Dataset.extra`` key of why a twin's ground truth was not used: the reasons, each once.
GROUND_TRUTH_NOTES = 'ground_truth_notes'


def _note_partial_ground_truth(datasets: list[Dataset]) -> list[Dataset]:
    """Say so when only some bags carry a twin's noise-free torque, on every dataset.

    Joined data has a label-noise floor only when every part has its noise-free torque, so a
    ground truth for some of the bags gives none at all: a warning names the bags with and
    without one, and it goes into each dataset's warnings and ground-truth notes.
    """
    with_truth = list(dict.fromkeys(bag_of(d) for d in datasets if d.tau_clean is not None))
    without = list(dict.fromkeys(bag_of(d) for d in datasets if d.tau_clean is None))
    if not with_truth or not without:
        return datasets
    carry = 'carries' if len(with_truth) == 1 else 'carry'
    note = (
        f'of the bags, only {", ".join(with_truth)} {carry} a twin ground truth (noise-free '
        f'torque); {", ".join(without)} {"does" if len(without) == 1 else "do"} not: the joined '
        'data gets no label-noise floor and no errors against the truth; evaluate the bags with '
        'a ground truth on their own for those figures'
    )
    _LOG.warning('%s', note)
    return [
        replace(
            d,
            extra={
                **d.extra,
                DATA_WARNINGS: [*d.extra.get(DATA_WARNINGS, ()), note],
                GROUND_TRUTH_NOTES: [*d.extra.get(GROUND_TRUTH_NOTES, ()), note],
            },
        )
        for d in datasets
    ]


def bag_of(dataset: Dataset) -> str:
    """The bag a dataset (one segment of it) was loaded from, else its source."""
    return str(dataset.extra.get('bag', dataset.source))


def datasets_by_bag(
    bags: Sequence[Path], datasets: Sequence[Dataset]
) -> list[tuple[Path, list[int]]]:
    """Per bag, the indices of its datasets (its segments, in order) in ``datasets``."""
    return [(bag, [i for i, d in enumerate(datasets) if bag_of(d) == str(bag)]) for bag in bags]


def _nominal_findings(
    recording: Recording, robot: RobotConfig, target: str, gravity: GravityTorque
) -> list[str]:
    """The label against the URDF's gravity torque, per joint: sign and scale (warnings)."""
    label = recording.current if target == 'motor' else recording.joint_torque
    if label is None:
        return []
    quantity = 'motor current' if target == 'motor' else 'joint torque'
    findings = gravity_findings(recording.position, label, robot, gravity, quantity=quantity)
    return [finding.text for finding in findings]


#: ``Dataset.extra`` key of what loading the recordings warned of (``dataset.content``).
DATA_WARNINGS = 'data_warnings'
#: A test part shorter than this [s] judges the models on too little motion for its RMSE to
#: stand for the robot's: said in the run's warnings (another stretch may differ severalfold).
MIN_TEST_S = 30.0


def _with_short_test_note(dataset: Dataset) -> Dataset:
    """The dataset; a test part shorter than ``MIN_TEST_S`` is warned of (logged, and kept)."""
    test_s = len(dataset.test_rows) * dataset.period_s
    if test_s >= MIN_TEST_S:
        return dataset
    note = (
        f'the test part holds {test_s:.1f} s of motion, less than {MIN_TEST_S:g} s: its RMSE '
        'judges the models on too little motion to stand for the robot (another stretch may '
        f'differ severalfold); record longer (at {1 - dataset.n_train / len(dataset.q):.0%} for '
        f'the test part, {MIN_TEST_S * len(dataset.q) / max(len(dataset.test_rows), 1):.0f} s '
        'or more)'
    )
    _LOG.warning('%s: %s', dataset.source, note)
    dataset.extra[DATA_WARNINGS] = [*dataset.extra.get(DATA_WARNINGS, ()), note]
    return dataset


def data_warnings(datasets: Sequence[Dataset]) -> list[str]:
    """The recordings' content warnings, each once, in order."""
    return list(dict.fromkeys(w for d in datasets for w in d.extra.get(DATA_WARNINGS, ())))


def combine_datasets(datasets: Sequence[Dataset]) -> Dataset:
    """Concatenate preprocessed recordings: all training parts first, then all test parts.

    The scalers are refitted on the concatenated training part. ``extra['segments']`` lists, per
    recording, its source and the [start, stop) rows of its training and test parts; stamps stay
    those of each recording (so they are not monotonic across a seam).
    """
    if not datasets:
        raise ConfigError('no dataset to combine')
    first = datasets[0]
    for other in datasets[1:]:
        if other.joints != first.joints or other.target != first.target:
            raise DatasetError(
                f'{other.source}: joints/target {other.joints}/{other.target} differ from '
                f'{first.source}: {first.joints}/{first.target}'
            )
        if (
            other.period_s != first.period_s
            or not np.array_equal(other.cutoff_hz, first.cutoff_hz)
            or other.mode != first.mode
            or other.controller_inputs != first.controller_inputs
        ):
            raise DatasetError(
                f'{other.source}: period, cut-offs or inputs differ from {first.source}'
            )
    if any(d.is_shuffled for d in datasets):
        joined = _joined_whole(datasets, [_mask(d) for d in datasets], first.regularise_report)
        return _with_short_test_note(joined)
    train_rows = [slice(0, d.n_train) for d in datasets]
    test_rows = [slice(d.n_train, len(d.q)) for d in datasets]
    segments: list[dict[str, Any]] = []
    start = 0
    for d in datasets:
        segments.append(
            {'source': d.source, 'bag': bag_of(d), 'train': [start, start + d.n_train]}
        )
        start += d.n_train
    n_train = start
    for d, segment in zip(datasets, segments, strict=True):
        stop = start + len(d.q) - d.n_train
        segment['test'] = [start, stop]
        start = stop

    pieces = [(d, rows) for d, rows in zip(datasets, train_rows, strict=True)]
    pieces += [(d, rows) for d, rows in zip(datasets, test_rows, strict=True)]
    return _with_short_test_note(
        _joined(
            datasets,
            pieces,
            n_train=n_train,
            segments=segments,
            regularise_report=first.regularise_report if len(datasets) == 1 else None,
        )
    )


def mask_sha256(mask: np.ndarray) -> str:
    """SHA-256 of a boolean row mask (its packed bits)."""
    return hashlib.sha256(np.packbits(np.asarray(mask, dtype=bool)).tobytes()).hexdigest()


def seen_rows(dataset: Dataset) -> int | np.ndarray:
    """What of a recording a run trained on: its first n rows, or a shuffled split's mask."""
    return _mask(dataset) if dataset.is_shuffled else dataset.n_train


def _mask(dataset: Dataset) -> np.ndarray:
    """(N,) True for a dataset's training rows."""
    mask = np.zeros(len(dataset.q), dtype=bool)
    mask[dataset.train_rows] = True
    return mask


def _joined_whole(
    datasets: Sequence[Dataset],
    seen: Sequence[np.ndarray],
    regularise_report: Any = None,
    target_scaler: MinMaxScaler | None = None,
) -> Dataset:
    """Whole recordings in order, their training (or seen) rows marked: a shuffled split.

    Each recording is one segment ``{'rows': [start, stop]}``; ``train_mask`` marks the rows
    of ``seen`` (per recording, True where a model trained on it).
    """
    segments, start = [], 0
    for d in datasets:
        segments.append({'source': d.source, 'bag': bag_of(d), 'rows': [start, start + len(d.q)]})
        start += len(d.q)
    mask = np.concatenate(seen)
    joined = _joined(
        datasets,
        [(d, slice(0, len(d.q))) for d in datasets],
        n_train=int(mask.sum()),
        segments=segments,
        target_scaler=target_scaler,
        regularise_report=regularise_report if len(datasets) == 1 else None,
        fit_rows=np.flatnonzero(mask) if mask.any() else None,
    )
    return replace(joined, train_mask=mask)


def concatenate_for_evaluation(
    datasets: Sequence[Dataset], seen: Sequence[int | np.ndarray], target_scaler: MinMaxScaler
) -> Dataset:
    """Concatenate whole preprocessed recordings, in order, as one dataset to evaluate on.

    Nothing of it is for training (``n_train`` is 0). Each recording is one segment in
    ``extra['segments']``: its first ``seen`` rows (the training part, when a model saw it) are
    its 'train' range, the rest its 'test' range, which is what is scored. The recordings stay
    whole so that a torque filtered like the labels is filtered over the whole recording, as the
    labels were. The label scaler is the run's.
    """
    if any(isinstance(n_seen, np.ndarray) for n_seen in seen):  # a shuffled run's bags
        masks = [
            n_seen if isinstance(n_seen, np.ndarray) else np.arange(len(d.q)) < n_seen
            for d, n_seen in zip(datasets, seen, strict=True)
        ]
        if all(m.all() for m in masks):
            raise DatasetError('no samples left to evaluate')
        return _joined_whole(datasets, masks, target_scaler=target_scaler)
    segments: list[dict[str, Any]] = []
    start = 0
    for d, n_seen in zip(datasets, seen, strict=True):
        stop = start + len(d.q)
        segments.append(
            {
                'source': d.source,
                'bag': bag_of(d),
                'train': [start, start + n_seen],
                'test': [start + n_seen, stop],
            }
        )
        start = stop
    if sum(s['test'][1] - s['test'][0] for s in segments) == 0:
        raise DatasetError('no samples left to evaluate')

    pieces = [(d, slice(0, len(d.q))) for d in datasets]
    return _joined(datasets, pieces, n_train=0, segments=segments, target_scaler=target_scaler)


def _joined(
    datasets: Sequence[Dataset],
    pieces: Sequence[tuple[Dataset, slice]],
    *,
    n_train: int,
    segments: list[dict[str, Any]],
    target_scaler: MinMaxScaler | None = None,
    regularise_report: Any = None,
    fit_rows: np.ndarray | None = None,
) -> Dataset:
    """One dataset of row ranges of recordings, in the order given.

    The input scaler is fitted on ``fit_rows``, else on the first ``n_train`` rows (all of them
    when 0); the target scaler likewise unless one is given.
    """
    first = datasets[0]

    def stack(name: str) -> np.ndarray:
        return np.concatenate([getattr(d, name)[rows] for d, rows in pieces], axis=0)

    def stack_motion(name: str) -> Motion:
        return Motion.concatenate([getattr(d, name).take(rows) for d, rows in pieces])

    q, v, a, tau = stack('q'), stack('v'), stack('a'), stack('tau')
    fit: slice | np.ndarray = slice(0, n_train) if n_train else slice(None)
    if fit_rows is not None:
        fit = fit_rows
    has_clean = all(d.tau_clean is not None for d in datasets)
    needed = join_needed_torque(pieces)
    return Dataset(
        joints=first.joints,
        target=first.target,
        period_s=first.period_s,
        stamps_ns=stack('stamps_ns'),
        q=q,
        v=v,
        a=a,
        tau=tau,
        tau_raw=stack('tau_raw'),
        n_train=n_train,
        input_scaler=MinMaxScaler().fit(np.hstack([q, v, a])[fit]),
        target_scaler=target_scaler or MinMaxScaler().fit(tau[fit]),
        cutoff_hz=first.cutoff_hz,
        filter_order=first.filter_order,
        mode=first.mode,
        controller=stack_motion('controller'),
        study=stack_motion('study'),
        controller_inputs=first.controller_inputs,
        tau_clean=stack('tau_clean') if has_clean else None,
        regularise_report=regularise_report,
        source=' + '.join(d.source for d in datasets),
        extra={
            'segments': segments,
            DATA_WARNINGS: data_warnings(datasets),
            GROUND_TRUTH_NOTES: list(
                dict.fromkeys(n for d in datasets for n in d.extra.get(GROUND_TRUTH_NOTES, ()))
            ),
            NEEDED_TORQUE_NOTES: list(
                dict.fromkeys(n for d in datasets for n in d.extra.get(NEEDED_TORQUE_NOTES, ()))
            ),
            **({} if needed is None else {NEEDED_TORQUE: needed}),
        },
    )


def segment_rows(dataset: Dataset, part: str) -> list[tuple[int, int]]:
    """Contiguous [start, stop) row ranges of ``part`` ('train', 'test' or 'all') per recording.

    Under a shuffled split a part is many short runs of neighbouring rows; 'all' is then one
    range per recording.
    """
    if dataset.is_shuffled:
        if part == 'all':
            return [(int(rows[0]), int(rows[-1]) + 1) for rows in dataset.recording_rows()]
        index = dataset.train_rows if part == 'train' else dataset.test_rows
        starts = [int(rows[0]) for rows in dataset.recording_rows()]
        # A run ends where the rows jump, and where a recording ends.
        breaks = np.flatnonzero((np.diff(index) > 1) | np.isin(index[1:], starts)) + 1
        return [(int(run[0]), int(run[-1]) + 1) for run in np.split(index, breaks) if len(run)]
    segments = dataset.extra.get('segments')
    if not segments:
        segments = [{'train': [0, dataset.n_train], 'test': [dataset.n_train, len(dataset.q)]}]
    if part == 'all':
        return [(int(s[name][0]), int(s[name][1])) for s in segments for name in ('train', 'test')]
    return [(int(s[part][0]), int(s[part][1])) for s in segments]


def training_data_summary(
    bags: Sequence[Path], dataset: Dataset, data: TrainingData
) -> dict[str, Any]:
    """What a run was trained on, for run.json and each model.json: bags, hashes and sizes.

    Under a shuffled split each bag entry also holds its sample count and the SHA-256 of its
    training mask, so that ``evaluate`` can tell whether it rebuilt the very same split.
    """
    entries: list[dict[str, Any]] = [
        {'path': str(b), 'absolute_path': str(Path(b).resolve()), 'sha256': bag_sha256(b)}
        for b in bags
    ]
    if dataset.train_mask is not None:
        segments = dataset.extra['segments']
        for entry in entries:
            rows = [
                rows
                for rows, segment in zip(dataset.recording_rows(), segments, strict=True)
                if segment.get('bag', segment['source']) == entry['path']
            ]
            mask = np.concatenate([dataset.train_mask[r] for r in rows])
            entry['n_samples'] = len(mask)
            entry['train_mask_sha256'] = mask_sha256(mask)
    return {
        'bags': entries,
        'data_sha256': data_sha256(dataset),
        'n_samples': len(dataset.q),
        'n_train': dataset.n_train,
        'n_fit': data.n_fit,
        'n_validation': dataset.n_train - data.n_fit,
        'segments': dataset.extra['segments'],
        DATA_WARNINGS: data_warnings([dataset]),
    }
