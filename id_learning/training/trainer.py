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

This module holds the two entry points and runs their steps in order; the steps live in
``training.datasets`` (loading), ``training.fitting``, ``training.measure`` (errors, timings,
the report) and ``training.run_folder`` (the files). Their public names are re-exported here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset, MinMaxScaler, PreprocessConfig, Target
from id_learning.errors import CheckpointError, TrainingError
from id_learning.evaluation.study import StudyTable
from id_learning.models.artifact import ArtifactExtra, _git_commit, robot_fingerprint
from id_learning.models.data import TrainingData
from id_learning.models.fitting import configure_torch
from id_learning.models.registry import save_model
from id_learning.outputs import ResultFolder, result_folder
from id_learning.robot.config import RobotConfig
from id_learning.training.datasets import (
    bag_sha256,
    combine_datasets,
    concatenate_for_evaluation,
    data_sha256,
    datasets_by_bag,
    load_datasets,
    mask_sha256,
    preprocess_from_dict,
    preprocess_to_dict,
    seen_rows,
    segment_rows,
    training_data_summary,
)
from id_learning.training.fitting import (
    TRAIN_THREADS,
    ModelResult,
    fit_models,
    resolve_overrides,
)
from id_learning.training.measure import (
    evaluate_models,
    measure_inference,
    predict_rows,
    write_run_report,
)
from id_learning.training.run_folder import (
    ARTIFACTS_KEY,
    METRICS_FILE,
    MODELS_DIR,
    REPORT_FILE,
    RUN_FILE,
    load_run_model,
    machine_info,
    metrics_document,
    read_run,
    refuse_training_samples,
    run_document,
    save_models,
    write_json,
)
from id_learning.training.run_identity import RUN_IDENTITY_KEY, check_run_unchanged, run_identity

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

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class RunResult:
    """What ``train_run`` made."""

    out: Path
    dataset: Dataset
    models: dict[str, ModelResult]
    metrics: dict[str, Any]
    report: Path
    #: Kinds whose fit failed, with why (the others were fitted, saved and scored).
    failures: dict[str, str] = field(default_factory=dict)

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


def train_run(
    bags: Sequence[Path],
    robot: RobotConfig,
    target: Target,
    kinds: Sequence[str],
    out: Path,
    *,
    hyper: dict[str, dict[str, Any]] | None = None,
    max_seconds_per_model: float | None = None,
    progress: bool = True,
    device: str = 'auto',
    preprocess: PreprocessConfig | None = None,
    study_table: StudyTable | None = None,
    overwrite: bool = False,
    trim_unpaired_tail: bool = False,
    announce: Callable[[str], None] | None = None,
) -> RunResult:
    """Train models on bags and write a run folder (models, metrics.json, report.md).

    Args:
        bags: bag folders; each is filtered and split 70/30 on its own (in time, or drawn at
            random: ``preprocess.split``).
        robot: the robot the bags were recorded on.
        target: 'motor' (tau_u from currents) or 'joint' (measured joint torque).
        kinds: model kinds to train (registry names), in the order to train and report them.
        out: run folder to write: written into ``<out>.partial`` (each model as soon as it is
            fitted) and renamed to ``out`` when complete (``id_learning.outputs``).
        hyper: per kind, hyper-parameter overrides (registry names of the config fields).
        max_seconds_per_model: wall-clock budget per model fit [s] (the identification and the
            diagnosis of the training part included), or None for the models' own.
        progress: show progress bars.
        device: 'auto' (CUDA when present), 'cpu' or 'cuda'.
        preprocess: preprocessing settings (default: ``PreprocessConfig()``), with ``target``.
        study_table: the study's Table 1 for the report (``evaluation.study``), if given.
        overwrite: replace a result already in ``out`` (or an interrupted run beside it);
            without it such a result is left intact. Never replaces an input or a folder that
            is not an id_learning result.
        trim_unpaired_tail: drop a torn recording's last unpaired messages, with a warning.
        announce: called with a line as each model is saved (a quiet run says how far it got).

    Raises:
        ConfigError: unknown kind or hyper-parameter, or an unavailable device.
        OutputError: ``out`` is refused (holds a result and ``overwrite`` is not set, another
            process writes it, not a folder, ...), or a write failed (path and OS reason).
        DatasetError, BagError: a bag is unusable.
        TrainingError: no model could be fitted. A model that fails while others fit is
            reported in ``RunResult.failures``, run.json, metrics.json and the report instead.
    """
    kinds = list(dict.fromkeys(kinds))
    config = replace(preprocess or PreprocessConfig(), target=target)
    resolved_device, overrides = resolve_overrides(
        kinds, hyper or {}, max_seconds=max_seconds_per_model, device=device
    )
    # The study's networks are small (2x64, 2x128): intra-op threads cost more than they give.
    # Measured on a shared 2-core machine: a DeLaN step took 14 ms on one thread, 1.4 s on two.
    configure_torch(TRAIN_THREADS)
    bags = [Path(b) for b in bags]
    # Written into OUT.partial, renamed to OUT when complete (``id_learning.outputs``).
    with result_folder(Path(out), command='train', force=overwrite, inputs=bags) as folder:
        # Bad bags are refused before anything but the partial folder is written.
        dataset = combine_datasets(
            load_datasets(
                bags, robot, config, progress=progress, trim_unpaired_tail=trim_unpaired_tail
            )
        )
        results, failures, metrics = _write_run(
            folder,
            bags,
            dataset,
            robot=robot,
            kinds=kinds,
            overrides=overrides,
            config=config,
            device=resolved_device,
            max_seconds_per_model=max_seconds_per_model,
            study_table=study_table,
            progress=progress,
            announce=announce,
        )
    out = folder.out
    moved = {k: replace(r, folder=out / MODELS_DIR / k) for k, r in results.items()}
    return RunResult(out, dataset, moved, metrics, out / REPORT_FILE, failures)


def _write_run(
    folder: ResultFolder,
    bags: list[Path],
    dataset: Dataset,
    *,
    robot: RobotConfig,
    kinds: list[str],
    overrides: dict[str, dict[str, Any]],
    config: PreprocessConfig,
    device: str,
    max_seconds_per_model: float | None,
    study_table: StudyTable | None,
    progress: bool,
    announce: Callable[[str], None] | None,
) -> tuple[dict[str, ModelResult], dict[str, str], dict[str, Any]]:
    """Fit, save, score and report into ``folder.work``; (results, failures, metrics)."""
    out = folder.work
    (out / MODELS_DIR).mkdir(parents=True, exist_ok=True)
    data = TrainingData(dataset, robot)
    scale = dataset.target_scaler.scale()
    preprocessing = preprocess_to_dict(config, dataset)
    training_data = training_data_summary(bags, dataset, data)
    run = run_document(
        robot=robot,
        kinds=kinds,
        device=device,
        max_seconds_per_model=max_seconds_per_model,
        preprocessing=preprocessing,
        target_scaler=dataset.target_scaler,
        training_data=training_data,
    )
    write_json(out / RUN_FILE, run)

    results, failures = _fit_and_save(
        data, kinds, overrides, folder, run, progress=progress, announce=announce
    )
    rows = segment_rows(dataset, 'test')
    table, predictions = evaluate_models(results, dataset, rows, scale, timing=True)
    run[ARTIFACTS_KEY] = save_models(
        results,
        table,
        preprocessing=preprocessing,
        target_scaler=dataset.target_scaler,
        training_data=training_data,
    )
    evaluated_on = _test_part_text(config)
    report_path, findings = write_run_report(
        title=f'Training run: {len(results)} models, {config.target} torque labels',
        out=out,
        dataset=dataset,
        robot=robot,
        results=results,
        rows=rows,
        scale=scale,
        evaluated_on=evaluated_on,
        predictions=predictions,
        study_table=study_table,
    )
    metrics = metrics_document(
        'training',
        target=config.target,
        robot=robot,
        dataset=dataset,
        evaluated_on=evaluated_on,
        rows=rows,
        scale=scale,
        bags=training_data['bags'],
        table=table,
        findings=findings,
        machine=run['machine'],
        git_commit=run['git_commit'],
    )
    _add_failures(metrics, report_path, failures, results)
    write_json(out / METRICS_FILE, metrics)
    run['status'] = 'complete'
    write_json(out / RUN_FILE, run)
    return results, failures, metrics


def _test_part_text(config: PreprocessConfig) -> str:
    """Which samples a run's figures are measured on, in words."""
    share = f'{1 - config.train_fraction:.0%}'
    if config.split == 'shuffled':
        return (
            f'the test part ({share} of the samples drawn at random, seed {config.split_seed}) '
            'of each training bag'
        )
    return f'the test part (last {share} in time) of each training bag'


def _add_failures(
    metrics: dict[str, Any],
    report: Path,
    failures: dict[str, str],
    results: dict[str, ModelResult],
) -> None:
    """Name the fits their budget cut short and the models that failed, in metrics and report."""
    cut = {k: r.metrics['cut_short'] for k, r in results.items() if r.metrics.get('cut_short')}
    sections = (
        ('cut_short', 'Fits cut short by their time budget', cut, '; '.join),
        ('failed', 'Models that failed', failures, str),
    )
    for key, title, entries, text in sections:
        if entries:
            metrics[key] = entries
            with report.open('a', encoding='utf-8') as out:
                out.write(f'\n## {title}\n\n')
                out.writelines(f'- `{kind}`: {text(why)}\n' for kind, why in entries.items())


def _fit_and_save(
    data: TrainingData,
    kinds: list[str],
    overrides: dict[str, dict[str, Any]],
    folder: ResultFolder,
    run: dict[str, Any],
    *,
    progress: bool,
    announce: Callable[[str], None] | None = None,
) -> tuple[dict[str, ModelResult], dict[str, str]]:
    """Fit every kind, saving each as soon as it is fitted; run.json records the failures.

    Each model is saved (atomically) into the partial folder as soon as it is fitted, where a
    user sees it at once; from then on a failure keeps the partial folder with what it holds.

    Raises:
        TrainingError: no kind could be fitted.
    """
    out = folder.work
    extra = ArtifactExtra(
        preprocessing=run['preprocessing'],
        target_scaler=run['target_scaler'],
        training_data=run['training_data'],
    )
    # run.json lists the models saved so far: an interrupted run says how far it got.
    run['requested_kinds'], run['kinds'] = list(kinds), []
    write_json(out / RUN_FILE, run)

    def save_at_once(result: ModelResult) -> None:  # metrics are added once all are scored
        save_model(result.model, result.folder, extra=extra)
        folder.keep = True
        run['kinds'].append(result.kind)
        write_json(out / RUN_FILE, run)
        if announce is not None:
            cut = result.metrics.get('cut_short')
            announce(
                f'{result.kind}: fitted in {result.metrics["train_seconds"]:.0f} s, saved to '
                f'{result.folder}'
                + (f' (cut short by its budget: {"; ".join(cut)})' if cut else '')
            )

    results, failures = fit_models(
        data, data.robot, kinds, overrides, out / MODELS_DIR, progress=progress,
        on_fitted=save_at_once,
    )  # fmt: skip
    # Fitted cheapest first; listed, evaluated and reported in the order asked for.
    run['kinds'] = [kind for kind in kinds if kind in run['kinds']]
    if failures:
        run['failed'] = failures
    write_json(out / RUN_FILE, run)
    if not results:
        bags = ', '.join(str(b['path']) for b in run['training_data']['bags'])
        raise TrainingError(
            f'no model could be fitted on {bags}: '
            + '; '.join(f'{kind}: {why}' for kind, why in failures.items())
        )
    return results, failures


def _load_models(run_dir: Path, run: dict[str, Any], robot: RobotConfig) -> dict[str, ModelResult]:
    """Load every model of a run; their metrics are filled in when they are evaluated."""
    results: dict[str, ModelResult] = {}
    # An interrupted run lists its models in the order they were fitted: report them as asked.
    order = {kind: k for k, kind in enumerate(run.get('requested_kinds', run['kinds']))}
    for kind in sorted(run['kinds'], key=lambda kind: order.get(kind, len(order))):
        model = load_run_model(run_dir, run, kind, robot)
        results[kind] = ModelResult(kind, model, run_dir / MODELS_DIR / kind, {})
    _say_what_does_not_belong(run_dir, run, results)
    return results


def _say_what_does_not_belong(
    run_dir: Path, run: dict[str, Any], results: dict[str, ModelResult]
) -> None:
    """Warn of what a hand-assembled run holds.

    Entries of models/ that run.json does not list; models fitted on other inputs than the
    others (copied in from another run).
    """
    from id_learning.models.artifact import METADATA_FILE, artifact_inputs, read_metadata

    listed = set(run['kinds'])
    stray = sorted(p.name for p in (run_dir / MODELS_DIR).iterdir() if p.name not in listed)
    if stray:
        _LOG.warning('%s: %s hold(s) %s, which run.json does not list: ignored', run_dir,
                     MODELS_DIR, ', '.join(stray))  # fmt: skip
    fitted_on: dict[str, list[str]] = {}
    for kind, result in results.items():
        _, fitting = artifact_inputs(read_metadata(result.folder / METADATA_FILE))
        fitted_on.setdefault('study' if fitting is None else fitting.name, []).append(kind)
    if len(fitted_on) > 1:
        groups = '; '.join(f'{name}: {", ".join(kinds)}' for name, kinds in fitted_on.items())
        _LOG.warning('%s: its models were fitted on different inputs (%s): a model copied '
                     'in from another run is not compared on equal terms', run_dir,
                     groups)  # fmt: skip


def _unseen_parts(
    bags: list[Path], datasets: list[Dataset], run: dict[str, Any]
) -> tuple[list[int | np.ndarray], list[str]]:
    """Per dataset (a bag's segment), the rows the run's models saw, and a sentence per bag.

    A training bag of the run contributes its test part only; any other bag all of it.
    """
    trained_on = {entry['sha256']: entry for entry in run['training_data']['bags']}
    seen: list[int | np.ndarray] = [0] * len(datasets)
    parts: list[str] = []
    for bag, indices in datasets_by_bag(bags, datasets):
        entry = trained_on.get(bag_sha256(bag))
        if entry is None:
            parts.append(f'{bag}: whole recording')
            continue
        rows = [seen_rows(datasets[i]) for i in indices]
        stored = entry.get('train_mask_sha256')
        masks = [r for r in rows if isinstance(r, np.ndarray)]
        if masks and stored is not None and mask_sha256(np.concatenate(masks)) != stored:
            n_now = sum(len(m) for m in masks)
            raise CheckpointError(
                f"{bag}: the run's shuffled split could not be rebuilt ({n_now} samples "
                f'now, {entry.get("n_samples")} then, or another random stream): its training '
                'samples cannot be told from its test samples'
            )
        for i, r in zip(indices, rows, strict=True):
            seen[i] = r
        parts.append(f'{bag}: test part only (a training bag of the run)')
    return seen, parts


def _add_training_numbers(results: dict[str, ModelResult]) -> None:
    """Copy each model's training time and history from its model.json into its metrics."""
    from id_learning.models.artifact import METADATA_FILE, read_metadata

    for result in results.values():
        trained = read_metadata(result.folder / METADATA_FILE)
        result.metrics['train_seconds'] = trained.get('metrics', {}).get('train_seconds')
        result.metrics['history'] = trained.get('train_history')


def evaluate_run(
    run_dir: Path,
    bags: Sequence[Path],
    robot: RobotConfig,
    out: Path,
    *,
    progress: bool = True,
    force: bool = False,
) -> EvaluationResult:
    """Evaluate every model of a run on other recordings; write metrics.json and report.md.

    The recordings are preprocessed with the run's stored settings (target, cut-offs, filter
    order) and errors are normalised with the run's training label scaler, so the numbers read
    like the run's own. What is evaluated: the whole of each recording, which the models never
    saw; a bag that was one of the run's training bags (same SHA-256) contributes only its test
    part, because its training part is not new data.

    ``out`` is written whole or not at all (``id_learning.outputs``); ``force`` replaces an
    earlier result there, but never the evaluated run or a bag. metrics.json records the run's
    identity beside its path (``run_identity``).

    Raises:
        CheckpointError: the run is incomplete, or it or a model does not match ``robot``
            (load_model verifies robot name, joints and order, URDF hash, drives, units and
            weight hashes), or the run was replaced while it was evaluated (nothing written).
        OutputError: ``out`` is refused, or a write failed.
        DatasetError, BagError: a bag is unusable.
    """
    run_dir, out = Path(run_dir), Path(out)
    bags = [Path(b) for b in bags]
    run = read_run(run_dir)
    fingerprint = robot_fingerprint(robot)
    if run.get('robot', {}).get('joints') != fingerprint['joints']:
        raise CheckpointError(
            f'{run_dir}: run joints {run.get("robot", {}).get("joints")} do not match robot '
            f'{robot.name} joints {fingerprint["joints"]}'
        )
    identity = run_identity(run_dir, run, run['kinds'])  # before the models are loaded
    with result_folder(out, command='evaluate', force=force, inputs=[run_dir, *bags]) as folder:
        metrics, results, dataset = _evaluate_into(
            folder.work, run_dir, run, bags, robot, progress=progress, identity=identity
        )
        check_run_unchanged(run_dir, identity, 'evaluate')  # not in place before it passes
    return EvaluationResult(folder.out, dataset, results, metrics, folder.out / REPORT_FILE)


def _evaluate_into(
    out: Path,
    run_dir: Path,
    run: dict[str, Any],
    bags: list[Path],
    robot: RobotConfig,
    *,
    progress: bool,
    identity: dict[str, Any],
) -> tuple[dict[str, Any], dict[str, ModelResult], Dataset]:
    """``evaluate_run``'s work, written into ``out``; (metrics, models, evaluated data).

    ``identity``: the run's (``run_identity``), recorded in metrics.json.
    """
    config = preprocess_from_dict(run['preprocessing'])
    configure_torch(TRAIN_THREADS)
    results = _load_models(run_dir, run, robot)
    datasets = load_datasets(bags, robot, config, progress=progress)
    refuse_training_samples(bags, run, run_dir, robot)
    seen, parts = _unseen_parts(bags, datasets, run)
    target_scaler = MinMaxScaler.from_dict(run['target_scaler'])
    dataset = concatenate_for_evaluation(datasets, seen, target_scaler)
    rows = segment_rows(dataset, 'test')
    scale = target_scaler.scale()
    table, predictions = evaluate_models(results, dataset, rows, scale, timing=True)
    _add_training_numbers(results)
    evaluated_on = '; '.join(parts)
    _, findings = write_run_report(
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
    metrics = metrics_document(
        'evaluation',
        run=str(run_dir),
        target=config.target,
        robot=robot,
        dataset=dataset,
        evaluated_on=evaluated_on,
        rows=rows,
        scale=scale,
        bags=[{'path': str(b), 'sha256': bag_sha256(b)} for b in bags],
        table=table,
        findings=findings,
        machine=machine_info(),
        git_commit=_git_commit(),
    )
    metrics[RUN_IDENTITY_KEY] = identity  # the path may hold another run later
    write_json(out / METRICS_FILE, metrics)
    return metrics, results, dataset
