"""Offline training and evaluation runs: bags in, fitted models, metrics and a report out.

A run folder holds::

    RUN_DIR/
      run.json             how the run was made: robot, bags and hashes, preprocessing, scaler
      metrics.json         per model: per-joint test errors, train time, inference time
      report.md, *.png     the study's exhibits on this data (evaluation.report)
      models/<kind>/       one artifact per model: weights.safetensors + model.json

Several bags: each is preprocessed on its own (the zero-phase filter and the differentiation
must not run across the seam of two recordings) and split 70/30 in time on its own; the training
parts are concatenated in bag order, then the test parts. The label scaler is refitted on all
training parts. The validation part used for early stopping is the tail of the concatenated
training part, i.e. the end of the last bag's training part. Sequence models (LSTM) may see a
few windows that straddle a seam during fitting; predictions for metrics are made per bag.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import time
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from id_learning.dataset.inputs import InputDefinition, Motion
from id_learning.dataset.preprocess import Dataset, MinMaxScaler, PreprocessConfig, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.errors import CheckpointError, ConfigError, DatasetError
from id_learning.models.artifact import _git_commit, robot_fingerprint
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.data import DiagnosedEffects, TrainingData
from id_learning.models.fitting import configure_torch, select_device
from id_learning.robot.config import RobotConfig
from id_learning.twin import read_noise_free_torque

__all__ = [
    'METRICS_FILE',
    'REPORT_FILE',
    'RUN_FILE',
    'EvaluationResult',
    'ModelResult',
    'RunResult',
    'bag_sha256',
    'combine_datasets',
    'concatenate_for_evaluation',
    'data_sha256',
    'evaluate_run',
    'load_datasets',
    'measure_inference',
    'predict_rows',
    'preprocess_from_dict',
    'preprocess_to_dict',
    'read_run',
    'segment_rows',
    'train_run',
]

TRAIN_THREADS = 1  # torch intra-op threads for fitting and evaluating the small networks

_LOG = logging.getLogger(__name__)

RUN_FORMAT = 'id_learning.run/1'
METRICS_FORMAT = 'id_learning.metrics/1'
RUN_FILE = 'run.json'
METRICS_FILE = 'metrics.json'
REPORT_FILE = 'report.md'
MODELS_DIR = 'models'
#: One-sample latency: calls timed after a few warm-up calls.
LATENCY_CALLS = 200
LATENCY_WARMUP = 10


@dataclass(frozen=True, eq=False)
class ModelResult:
    """One fitted (or loaded) model of a run and its numbers.

    Attributes:
        kind: registry name.
        model: the fitted model.
        folder: its artifact folder.
        metrics: the metrics.json entry (errors, timings, training summary).
    """

    kind: str
    model: InverseDynamicsModel
    folder: Path
    metrics: dict[str, Any]


@dataclass(frozen=True, eq=False)
class RunResult:
    """What ``train_run`` made."""

    out: Path
    dataset: Dataset
    models: dict[str, ModelResult]
    metrics: dict[str, Any]
    report: Path

    @property
    def metrics_path(self) -> Path:
        """The run's metrics.json."""
        return self.out / METRICS_FILE


@dataclass(frozen=True, eq=False)
class EvaluationResult:
    """What ``evaluate_run`` made."""

    out: Path
    dataset: Dataset
    models: dict[str, ModelResult]
    metrics: dict[str, Any]
    report: Path


# -- data ------------------------------------------------------------------------------------


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
            jitter_tolerance=float(data['jitter_tolerance']),
            min_filter_periods=float(data['min_filter_periods']),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f'preprocessing settings are incomplete or invalid: {err}') from err


def load_datasets(
    bags: Sequence[Path], robot: RobotConfig, config: PreprocessConfig, *, progress: bool = True
) -> list[Dataset]:
    """Load and preprocess each bag on its own (filtering never crosses two recordings)."""
    if not bags:
        raise ConfigError('no bag given: pass at least one --bag')
    datasets = []
    for bag in tqdm(bags, desc='loading bags', unit='bag', disable=not progress or len(bags) < 2):
        recording = load_recording(
            Path(bag), robot, require_current=config.target == 'motor', progress=progress
        )
        dataset = prepare_dataset(recording, robot, config)
        clean = read_noise_free_torque(bag, config.target, dataset.stamps_ns)
        datasets.append(replace(dataset, tau_clean=clean) if clean is not None else dataset)
        _LOG.info('%s: %d samples', bag, recording.n_samples)
    return datasets


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
    train_rows = [slice(0, d.n_train) for d in datasets]
    test_rows = [slice(d.n_train, len(d.q)) for d in datasets]
    segments: list[dict[str, Any]] = []
    start = 0
    for d in datasets:
        segments.append({'source': d.source, 'train': [start, start + d.n_train]})
        start += d.n_train
    n_train = start
    for d, segment in zip(datasets, segments, strict=True):
        stop = start + len(d.q) - d.n_train
        segment['test'] = [start, stop]
        start = stop

    def stack(name: str) -> np.ndarray:
        parts = [getattr(d, name)[rows] for d, rows in zip(datasets, train_rows, strict=True)]
        parts += [getattr(d, name)[rows] for d, rows in zip(datasets, test_rows, strict=True)]
        return np.concatenate(parts, axis=0)

    def stack_motion(name: str) -> Motion:
        parts = [getattr(d, name).take(rows) for d, rows in zip(datasets, train_rows, strict=True)]
        parts += [getattr(d, name).take(rows) for d, rows in zip(datasets, test_rows, strict=True)]
        return Motion.concatenate(parts)

    q, v, a, tau = stack('q'), stack('v'), stack('a'), stack('tau')
    has_clean = all(d.tau_clean is not None for d in datasets)
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
        input_scaler=MinMaxScaler().fit(np.hstack([q, v, a])[:n_train]),
        target_scaler=MinMaxScaler().fit(tau[:n_train]),
        cutoff_hz=first.cutoff_hz,
        filter_order=first.filter_order,
        mode=first.mode,
        controller=stack_motion('controller'),
        study=stack_motion('study'),
        controller_inputs=first.controller_inputs,
        tau_clean=stack('tau_clean') if has_clean else None,
        regularise_report=first.regularise_report if len(datasets) == 1 else None,
        source=' + '.join(d.source for d in datasets),
        extra={'segments': segments},
    )


def concatenate_for_evaluation(
    datasets: Sequence[Dataset], seen: Sequence[int], target_scaler: MinMaxScaler
) -> Dataset:
    """Concatenate whole preprocessed recordings, in order, as one dataset to evaluate on.

    Nothing of it is for training (``n_train`` is 0). Each recording is one segment in
    ``extra['segments']``: its first ``seen`` rows (the training part, when a model saw it) are
    its 'train' range, the rest its 'test' range, which is what is scored. The recordings stay
    whole so that a torque filtered like the labels is filtered over the whole recording, as the
    labels were. The label scaler is the run's.
    """
    segments: list[dict[str, Any]] = []
    start = 0
    for d, n_seen in zip(datasets, seen, strict=True):
        stop = start + len(d.q)
        segments.append(
            {'source': d.source, 'train': [start, start + n_seen], 'test': [start + n_seen, stop]}
        )
        start = stop
    if sum(s['test'][1] - s['test'][0] for s in segments) == 0:
        raise DatasetError('no samples left to evaluate')

    def stack(name: str) -> np.ndarray:
        return np.concatenate([getattr(d, name) for d in datasets], axis=0)

    def stack_motion(name: str) -> Motion:
        return Motion.concatenate([getattr(d, name) for d in datasets])

    q, v, a = stack('q'), stack('v'), stack('a')
    first = datasets[0]
    has_clean = all(d.tau_clean is not None for d in datasets)
    return Dataset(
        joints=first.joints,
        target=first.target,
        period_s=first.period_s,
        stamps_ns=stack('stamps_ns'),
        q=q,
        v=v,
        a=a,
        tau=stack('tau'),
        tau_raw=stack('tau_raw'),
        n_train=0,
        input_scaler=MinMaxScaler().fit(np.hstack([q, v, a])),
        target_scaler=target_scaler,
        cutoff_hz=first.cutoff_hz,
        filter_order=first.filter_order,
        mode=first.mode,
        controller=stack_motion('controller'),
        study=stack_motion('study'),
        controller_inputs=first.controller_inputs,
        tau_clean=stack('tau_clean') if has_clean else None,
        source=' + '.join(d.source for d in datasets),
        extra={'segments': segments},
    )


def segment_rows(dataset: Dataset, part: str) -> list[tuple[int, int]]:
    """Contiguous [start, stop) row ranges of ``part`` ('train', 'test' or 'all') per recording."""
    segments = dataset.extra.get('segments')
    if not segments:
        segments = [{'train': [0, dataset.n_train], 'test': [dataset.n_train, len(dataset.q)]}]
    if part == 'all':
        return [(int(s[name][0]), int(s[name][1])) for s in segments for name in ('train', 'test')]
    return [(int(s[part][0]), int(s[part][1])) for s in segments]


# -- models ----------------------------------------------------------------------------------


def model_overrides(
    kind: str,
    hyper: dict[str, dict[str, Any]],
    *,
    max_seconds: float | None = None,
    device: str = 'auto',
) -> dict[str, Any]:
    """The hyper-parameter overrides of one kind: the user's, a time budget and the device."""
    from id_learning.models.registry import MODEL_KINDS

    if kind not in MODEL_KINDS:
        raise ConfigError(f'unknown model kind {kind!r}; known kinds: {sorted(MODEL_KINDS)}')
    names = {item.name for item in fields(MODEL_KINDS[kind][0])}
    overrides = dict(hyper.get(kind, {}))
    # Settings a kind does not have (RNEA+LQ is a least-squares fit: no budget, no device) are
    # left out rather than refused: they are run-wide, not the user's per-kind choice.
    if max_seconds is not None and 'max_seconds' in names:
        overrides.setdefault('max_seconds', max_seconds)
    if 'device' in names:
        overrides.setdefault('device', device)
    return overrides


def _history(model: InverseDynamicsModel) -> dict[str, Any] | None:
    for name in ('history_', 'train_history_'):
        history = getattr(model, name, None)
        if history is not None:
            return history.to_dict() if hasattr(history, 'to_dict') else dict(history)
    return None


def _window(model: InverseDynamicsModel) -> int:
    """Samples one prediction needs: the sequence length of a sequence model, else 1."""
    if not model.is_sequence_model:
        return 1
    for name in ('sequence_length', 'window', 'seq_len'):
        value = getattr(model.config, name, None)
        if isinstance(value, int):
            return value
    return 1


def predict_rows(
    model: InverseDynamicsModel, dataset: Dataset, rows: Sequence[tuple[int, int]]
) -> np.ndarray:
    """Predictions (N, n) [N*m] for the given contiguous row ranges, each predicted on its own."""
    if not model.is_sequence_model:
        index = np.concatenate([np.arange(a, b) for a, b in rows])
        return model.predict(dataset.q[index], dataset.v[index], dataset.a[index])
    parts = [model.predict(dataset.q[a:b], dataset.v[a:b], dataset.a[a:b]) for a, b in rows]
    return np.concatenate(parts, axis=0)


def measure_inference(
    model: InverseDynamicsModel,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    *,
    calls: int = LATENCY_CALLS,
    repeats: int = 3,
    latency_threads: int = 1,
) -> dict[str, float]:
    """Inference time: batched per sample, and one-sample latency (median, p99).

    Args:
        model: a fitted model.
        q, v, a: (N, n) a contiguous run of states; the batched timing predicts all of it.
        calls: one-sample predictions timed (after warm-up calls).
        repeats: batched timings; the fastest counts (the others met a busy machine); 0 skips
            them.
        latency_threads: torch threads for the one-sample calls (restored afterwards).

    Returns:
        ``inference_seconds_per_sample`` (batched; absent when ``repeats`` is 0),
        ``latency_single_sample_median_s``,
        ``latency_single_sample_p99_s``, ``latency_window_samples`` (the samples one call gets:
        a sequence model's window), ``latency_threads`` and ``batched_threads``.
    """
    n = len(q)
    window = min(_window(model), n)
    model.predict(q[:window], v[:window], a[:window])
    batched = []
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict(q, v, a)
        batched.append(time.perf_counter() - start)
    threads = torch.get_num_threads()
    # A sequence model answers one sample from its window; its predict() would answer every
    # sample of the window, so time the one-window call the online predictor makes.
    predict_window = getattr(model, 'predict_window', None) if window > 1 else None
    inputs = np.hstack([q, v, a])
    latencies = []
    # One sample is too little work to share between threads; the online predictor runs with a
    # fixed small thread count, and on a busy machine more threads only add waiting.
    torch.set_num_threads(latency_threads)
    try:
        for k in range(LATENCY_WARMUP + calls):
            i = (k * 37) % max(n - window + 1, 1)
            if predict_window is not None:
                start = time.perf_counter()
                predict_window(inputs[i : i + window])
            else:
                args = (q[i : i + window], v[i : i + window], a[i : i + window])
                start = time.perf_counter()
                model.predict(*args)
            if k >= LATENCY_WARMUP:
                latencies.append(time.perf_counter() - start)
    finally:
        torch.set_num_threads(threads)
    timings: dict[str, float] = {}
    if batched:
        timings['inference_seconds_per_sample'] = min(batched) / n
    return {
        **timings,
        'latency_single_sample_median_s': float(np.median(latencies)),
        'latency_single_sample_p99_s': float(np.percentile(latencies, 99)),
        'latency_window_samples': window,
        'latency_threads': latency_threads,
        'batched_threads': threads,
    }


def _machine() -> dict[str, Any]:
    return {
        'host': platform.node(),
        'processor': platform.processor() or platform.machine(),
        'cpu_count': os.cpu_count(),
        'torch': torch.__version__,
        'torch_threads': torch.get_num_threads(),
        'cuda': torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


def _metric_notes(dataset: Dataset) -> dict[str, Any]:
    """What the metrics mean, and the label-noise floor where the noise-free torque is known."""
    from id_learning.evaluation.scoring import label_noise_floor

    floor = label_noise_floor(dataset)
    return {
        'metric': (
            "through_filter: each model on a controller's inputs along whole recordings, its "
            'torque low-passed like the labels, against the labels on the test part '
            "(rmse_nm = rmse_through_filter_nm); study_way: on the study's low-passed inputs, "
            'the torque against the labels as is'
        ),
        'inputs': dataset.controller_inputs.to_dict(),
        'label_filter': dataset.label_filter,
        'label_noise_floor_nm': None if floor is None else floor.tolist(),
    }


def _write_json(path: Path, document: dict[str, Any]) -> None:
    path.write_text(json.dumps(document, indent=1) + '\n', encoding='utf-8')


# -- runs ------------------------------------------------------------------------------------


def _evaluate(
    results: dict[str, ModelResult],
    dataset: Dataset,
    rows: list[tuple[int, int]],
    scale: np.ndarray,
    *,
    timing: bool,
) -> tuple[dict[str, dict[str, Any]], dict[str, np.ndarray]]:
    """Errors (and timings) of each model on the test rows; fills the ModelResult metrics.

    The errors are ``evaluation.scoring.score_model``'s: through the label filter first.

    Returns:
        The metrics entries and the predictions through the filter on the test rows
        (N_eval, n) [N*m], by kind.
    """
    from id_learning.evaluation.scoring import score_model

    table: dict[str, dict[str, Any]] = {}
    predictions: dict[str, np.ndarray] = {}
    for kind, result in results.items():
        start = time.perf_counter()
        score = score_model(result.model, dataset, scale)
        seconds = time.perf_counter() - start
        predictions[kind] = score.filtered
        entry = dict(score.metrics)
        if timing:
            a, b = max(rows, key=lambda r: r[1] - r[0])
            # Every sample is predicted twice (controller's and the study's inputs).
            entry['inference_seconds_per_sample'] = seconds / (2 * len(dataset.tau))
            motion = dataset.controller
            entry.update(
                measure_inference(
                    result.model, motion.q[a:b], motion.v[a:b], motion.a[a:b], repeats=0
                )
            )
        result.metrics.update(entry)
        table[kind] = result.metrics
    return table, predictions


def _report(
    *,
    title: str,
    out: Path,
    dataset: Dataset,
    robot: RobotConfig,
    results: dict[str, ModelResult],
    rows: list[tuple[int, int]],
    scale: np.ndarray,
    evaluated_on: str,
    predictions: dict[str, np.ndarray],
) -> tuple[Path, list[dict[str, Any]]]:
    from id_learning.evaluation.report import ReportInput, write_report
    from id_learning.evaluation.scoring import label_noise_floor

    report = ReportInput(
        title=title,
        robot=robot,
        dataset=dataset,
        rows=rows,
        evaluated_on=evaluated_on,
        target_scale=scale,
        models={kind: r.model for kind, r in results.items()},
        metrics={kind: r.metrics for kind, r in results.items()},
        predictions=predictions,
        noise_floor=label_noise_floor(dataset),
    )
    return write_report(report, out)


def _with_diagnosis(
    data: TrainingData, kinds: Sequence[str], overrides: dict[str, dict[str, Any]]
) -> tuple[TrainingData, dict[str, float]]:
    """Diagnose the training part once if a kind builds on its effects (no effects file given).

    Returns:
        The training data with the diagnosis, and per kind that uses it the seconds it took.
    """
    from id_learning.diagnosis import diagnose_training_part
    from id_learning.models.registry import make_config

    users = [k for k in kinds if getattr(make_config(k, **overrides[k]), 'effects', None) == '']
    if not users:
        return data, {}
    start = time.perf_counter()
    model, summary = diagnose_training_part(data.dataset, data.robot)
    seconds = time.perf_counter() - start
    _LOG.info('diagnosed the training part in %.1f s for %s', seconds, users)
    return replace(data, diagnosed=DiagnosedEffects(model, summary)), dict.fromkeys(users, seconds)


def train_run(
    bags: Sequence[Path],
    robot: RobotConfig,
    target: str,
    kinds: Sequence[str],
    out: Path,
    *,
    hyper: dict[str, dict[str, Any]] | None = None,
    max_seconds_per_model: float | None = None,
    progress: bool = True,
    device: str = 'auto',
    preprocess: PreprocessConfig | None = None,
) -> RunResult:
    """Train models on bags and write a run folder (models, metrics.json, report.md).

    Args:
        bags: bag folders; each is filtered and split 70/30 in time on its own.
        robot: the robot the bags were recorded on.
        target: 'motor' (tau_u from currents) or 'joint' (measured joint torque).
        kinds: model kinds to train (registry names), in the order to train and report them.
        out: run folder to write (created; files in it are overwritten).
        hyper: per kind, hyper-parameter overrides (registry names of the config fields).
        max_seconds_per_model: wall-clock budget per model fit [s], or None for the models' own.
        progress: show progress bars.
        device: 'auto' (CUDA when present), 'cpu' or 'cuda'.
        preprocess: preprocessing settings; the default is the study's, with ``target``.

    Raises:
        ConfigError: unknown kind or hyper-parameter, or an unavailable device.
        DatasetError, BagError: a bag is unusable.
    """
    from id_learning.models.registry import make_config, make_model, save_model

    hyper = hyper or {}
    kinds = list(dict.fromkeys(kinds))
    unknown = sorted(set(hyper) - set(kinds))
    if unknown:
        raise ConfigError(f'hyper-parameters given for kinds that are not trained: {unknown}')
    config = replace(preprocess or PreprocessConfig(), target=target)
    resolved_device = str(select_device(device))
    overrides = {
        kind: model_overrides(
            kind, hyper, max_seconds=max_seconds_per_model, device=resolved_device
        )
        for kind in kinds
    }
    for kind in kinds:  # refuse a bad hyper-parameter before hours of loading and fitting
        make_config(kind, **overrides[kind])
    # The study's networks are small (2x64, 2x128): intra-op threads cost more than they give.
    # Measured on a shared 2-core machine: a DeLaN step took 14 ms on one thread, 1.4 s on two.
    configure_torch(TRAIN_THREADS)
    out = Path(out)
    (out / MODELS_DIR).mkdir(parents=True, exist_ok=True)
    bags = [Path(b) for b in bags]
    datasets = load_datasets(bags, robot, config, progress=progress)
    dataset = combine_datasets(datasets)
    data = TrainingData(dataset, robot)
    scale = dataset.target_scaler.scale()
    preprocessing = preprocess_to_dict(config, dataset)
    training_data = {
        'bags': [{'path': str(b), 'sha256': bag_sha256(b)} for b in bags],
        'data_sha256': data_sha256(dataset),
        'n_samples': len(dataset.q),
        'n_train': dataset.n_train,
        'n_fit': data.n_fit,
        'n_validation': dataset.n_train - data.n_fit,
        'segments': dataset.extra['segments'],
    }
    run_document = {
        'format': RUN_FORMAT,
        'created_unix_s': time.time(),
        'git_commit': _git_commit(),
        'robot': robot_fingerprint(robot),
        'robot_config': str(Path(robot.source).resolve()) if robot.source else None,
        'kinds': kinds,
        'device': resolved_device,
        'max_seconds_per_model': max_seconds_per_model,
        'preprocessing': preprocessing,
        'target_scaler': dataset.target_scaler.to_dict(),
        'training_data': training_data,
        'machine': _machine(),
    }
    _write_json(out / RUN_FILE, run_document)

    data, diagnosis_seconds = _with_diagnosis(data, kinds, overrides)
    results: dict[str, ModelResult] = {}
    for kind in tqdm(kinds, desc='models', unit='model', disable=not progress):
        model = make_model(kind, robot, **overrides[kind])
        _LOG.info('fitting %s on %d samples', kind, data.n_fit)
        start = time.perf_counter()
        model.fit(data, progress=progress)
        # A kind built on the diagnosis of the training part pays for it too.
        seconds = time.perf_counter() - start + diagnosis_seconds.get(kind, 0.0)
        results[kind] = ModelResult(
            kind,
            model,
            out / MODELS_DIR / kind,
            {'train_seconds': seconds, 'history': _history(model)},
        )
        _LOG.info('%s fitted in %.1f s', kind, seconds)

    rows = segment_rows(dataset, 'test')
    table, predictions = _evaluate(results, dataset, rows, scale, timing=True)
    for kind, result in results.items():
        save_model(
            result.model,
            result.folder,
            extra={
                'preprocessing': preprocessing,
                'target_scaler': dataset.target_scaler.to_dict(),
                'training_data': training_data,
                'metrics': {k: v for k, v in table[kind].items() if k != 'history'},
                'train_history': table[kind].get('history'),
            },
        )
    evaluated_on = (
        f'the test part (last {1 - config.train_fraction:.0%} in time) of each training bag'
    )
    report_path, findings = _report(
        title=f'Training run: {len(kinds)} models, {target} torque labels',
        out=out,
        dataset=dataset,
        robot=robot,
        results=results,
        rows=rows,
        scale=scale,
        evaluated_on=evaluated_on,
        predictions=predictions,
    )
    metrics = {
        'format': METRICS_FORMAT,
        'kind': 'training',
        'target': target,
        'joints': list(robot.joints),
        'evaluated_on': evaluated_on,
        **_metric_notes(dataset),
        'n_samples': int(sum(b - a for a, b in rows)),
        'target_scale_nm': scale.tolist(),
        'bags': training_data['bags'],
        'models': table,
        'findings': findings,
        'machine': run_document['machine'],
        'git_commit': run_document['git_commit'],
    }
    _write_json(out / METRICS_FILE, metrics)
    return RunResult(out, dataset, results, metrics, report_path)


def read_run(run_dir: Path) -> dict[str, Any]:
    """Read a run folder's run.json.

    Raises:
        CheckpointError: missing, not JSON, or not a run document.
    """
    path = Path(run_dir) / RUN_FILE
    if not path.is_file():
        raise CheckpointError(f'{run_dir}: not a training run folder (no {RUN_FILE})')
    try:
        document = json.loads(path.read_text(encoding='utf-8'))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise CheckpointError(f'{path}: not valid JSON: {err}') from err
    if not isinstance(document, dict) or document.get('format') != RUN_FORMAT:
        raise CheckpointError(f'{path}: format is not {RUN_FORMAT!r}')
    return document


def evaluate_run(
    run_dir: Path,
    bags: Sequence[Path],
    robot: RobotConfig,
    out: Path,
    *,
    progress: bool = True,
) -> EvaluationResult:
    """Evaluate every model of a run on other recordings; write metrics.json and report.md.

    The recordings are preprocessed with the run's stored settings (target, cut-offs, filter
    order) and errors are normalised with the run's training label scaler, so the numbers read
    like the run's own. What is evaluated: the whole of each recording, which the models never
    saw; a bag that was one of the run's training bags (same SHA-256) contributes only its test
    part, because its training part is not new data.

    Raises:
        CheckpointError: the run or a model does not match ``robot`` (load_model verifies
            robot name, joints and order, URDF hash, drives, units and weight hashes).
        DatasetError, BagError: a bag is unusable.
    """
    from id_learning.models.registry import load_model

    run_dir, out = Path(run_dir), Path(out)
    run = read_run(run_dir)
    fingerprint = robot_fingerprint(robot)
    if run.get('robot', {}).get('joints') != fingerprint['joints']:
        raise CheckpointError(
            f'{run_dir}: run joints {run.get("robot", {}).get("joints")} do not match robot '
            f'{robot.name} joints {fingerprint["joints"]}'
        )
    config = preprocess_from_dict(run['preprocessing'])
    configure_torch(TRAIN_THREADS)
    results: dict[str, ModelResult] = {}
    for kind in run['kinds']:
        folder = run_dir / MODELS_DIR / kind
        results[kind] = ModelResult(kind, load_model(folder, robot, kind), folder, {})
    bags = [Path(b) for b in bags]
    datasets = load_datasets(bags, robot, config, progress=progress)
    trained_on = {entry['sha256'] for entry in run['training_data']['bags']}
    seen, parts = [], []
    for bag, part in zip(bags, datasets, strict=True):
        if bag_sha256(bag) in trained_on:
            seen.append(part.n_train)
            parts.append(f'{bag}: test part only (a training bag of the run)')
        else:
            seen.append(0)
            parts.append(f'{bag}: whole recording')
    target_scaler = MinMaxScaler.from_dict(run['target_scaler'])
    dataset = concatenate_for_evaluation(datasets, seen, target_scaler)
    rows = segment_rows(dataset, 'test')
    scale = target_scaler.scale()
    out.mkdir(parents=True, exist_ok=True)
    table, predictions = _evaluate(results, dataset, rows, scale, timing=True)
    for result in results.values():
        trained = json.loads((result.folder / 'model.json').read_text(encoding='utf-8'))
        result.metrics['train_seconds'] = trained.get('metrics', {}).get('train_seconds')
        result.metrics['history'] = trained.get('train_history')
    evaluated_on = '; '.join(parts)
    report_path, findings = _report(
        title=f'Evaluation of run {run_dir} on new recordings',
        out=out,
        dataset=dataset,
        robot=robot,
        results=results,
        rows=rows,
        scale=scale,
        evaluated_on=evaluated_on,
        predictions=predictions,
    )
    metrics = {
        'format': METRICS_FORMAT,
        'kind': 'evaluation',
        'run': str(run_dir),
        'target': config.target,
        'joints': list(robot.joints),
        'evaluated_on': evaluated_on,
        **_metric_notes(dataset),
        'n_samples': int(sum(b - a for a, b in rows)),
        'target_scale_nm': scale.tolist(),
        'bags': [{'path': str(b), 'sha256': bag_sha256(b)} for b in bags],
        'models': table,
        'findings': findings,
        'machine': _machine(),
        'git_commit': _git_commit(),
    }
    _write_json(out / METRICS_FILE, metrics)
    return EvaluationResult(out, dataset, results, metrics, report_path)
