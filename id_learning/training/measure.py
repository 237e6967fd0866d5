"""Measuring a run's fitted models: errors through the label filter, inference time, report.

The errors are ``evaluation.scoring``'s and the report is ``evaluation.report``'s (imported when
used: training depends on evaluation, never the reverse); this module times the models and
hands both the numbers. Shared by ``train_run`` and ``evaluate_run``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from id_learning.dataset.preprocess import Dataset
from id_learning.evaluation.study import StudyTable
from id_learning.models.base import InverseDynamicsModel, as_sequence_model
from id_learning.robot.config import RobotConfig
from id_learning.training.datasets import segment_rows
from id_learning.training.fitting import ModelResult

__all__ = [
    'LATENCY_CALLS',
    'LATENCY_WARMUP',
    'evaluate_models',
    'measure_inference',
    'metric_notes',
    'predict_rows',
    'write_run_report',
]

#: One-sample latency: calls timed after a few warm-up calls.
LATENCY_CALLS = 200
LATENCY_WARMUP = 10


def _window(model: InverseDynamicsModel) -> int:
    """Samples one prediction needs: the sequence length of a sequence model, else 1."""
    sequence = as_sequence_model(model)
    return 1 if sequence is None else sequence.sequence_length


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


def metric_notes(dataset: Dataset) -> dict[str, Any]:
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


def evaluate_models(
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
            # Timed on a stretch in time (a shuffled split's test rows form none).
            stretches = segment_rows(dataset, 'all') if dataset.is_shuffled else rows
            a, b = max(stretches, key=lambda r: r[1] - r[0])
            entry['inference_seconds_per_sample'] = seconds / score.predicted_samples
            motion = dataset.controller
            entry.update(
                measure_inference(
                    result.model, motion.q[a:b], motion.v[a:b], motion.a[a:b], repeats=0
                )
            )
        result.metrics.update(entry)
        table[kind] = result.metrics
    return table, predictions


def write_run_report(
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
    study_table: StudyTable | None = None,
) -> tuple[Path, list[dict[str, Any]]]:
    """Write report.md and its figures into ``out`` (``evaluation.report.write_report``).

    Returns:
        The report's path and the checked findings (JSON-ready).
    """
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
        study_table=study_table,
    )
    return write_report(report, out)
