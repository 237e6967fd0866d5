"""Offline training runs: bags in; fitted models, metrics.json and report.md out."""

from __future__ import annotations

from id_learning.training.trainer import (
    METRICS_FILE,
    REPORT_FILE,
    RUN_FILE,
    EvaluationResult,
    ModelResult,
    RunResult,
    bag_sha256,
    combine_datasets,
    concatenate_for_evaluation,
    data_sha256,
    evaluate_run,
    load_datasets,
    measure_inference,
    read_run,
    train_run,
)

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
    'read_run',
    'train_run',
]
