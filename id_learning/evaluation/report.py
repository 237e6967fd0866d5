"""The study's exhibits on our data: report.md with tables, PNG figures and checked findings.

Exhibits (after Trinh et al. 2025, see evaluation/study.py):

(a) per-joint test RMSE of all models through the label filter (``evaluation.scoring``), in N*m
    next to the label-noise floor and on the normalised [-1, 1] scale; against the noise-free
    torque on twin recordings; the study's way as a labelled extra, with the study's Table 1
    beside it when bundled;
(b) box plots of absolute test errors per joint and model;
(c) the dissipative torque each model implies on a test stretch of axis 1: measured label minus
    the nominal RNEA, against each model's prediction minus the nominal RNEA (and its friction
    component, where the model separates one);
(d) the share of the label torque per joint from inertia, gravity, Coriolis, rotor inertia and
    friction (nominal split, and the RNEA+LQ split when that model was trained);
(e) per label case, whether the study's findings hold, by explicit rules (``check_findings``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.evaluation.data_summary import nominal_components
from id_learning.evaluation.findings import (
    DISSIPATION_FREE_SHARE,
    FRICTION_SMOOTHING_VELOCITY,
    GAP_RECOVERED_FRACTION,
    HIGH_FRICTION_SHARE,
    LAGRANGIAN_COMPETITIVE_RATIO,
    Finding,
    check_findings,
    friction_share,
    high_friction_axes,
)
from id_learning.evaluation.metrics import absolute_errors
from id_learning.evaluation.physics_report import identified_physics_section
from id_learning.evaluation.report_figures import (
    dissipative_figure,
    plot_boxes,
    plot_rmse,
    plot_shares,
    torque_splits,
)
from id_learning.evaluation.report_tables import (
    MODES,
    accuracy_tables,
    findings_section,
    fmt,
    study_table,
    timing_table,
)
from id_learning.evaluation.scoring import score_model
from id_learning.evaluation.study import StudyTable
from id_learning.models.base import InverseDynamicsModel
from id_learning.outputs import write_text_atomic
from id_learning.robot.config import RobotConfig

__all__ = [
    'DISSIPATION_FREE_SHARE',
    'FRICTION_SMOOTHING_VELOCITY',
    'GAP_RECOVERED_FRACTION',
    'HIGH_FRICTION_SHARE',
    'LAGRANGIAN_COMPETITIVE_RATIO',
    'Finding',
    'ReportInput',
    'check_findings',
    'friction_share',
    'high_friction_axes',
    'write_report',
]


@dataclass(frozen=True, eq=False)
class ReportInput:
    """Everything a report shows.

    Attributes:
        title: first heading.
        robot: the robot.
        dataset: the preprocessed data (all rows; shares use all of them).
        rows: the evaluated [start, stop) row ranges of ``dataset``, each contiguous in time.
        evaluated_on: a sentence saying which data ``rows`` are.
        target_scale: (n,) half ranges of the training labels [N*m].
        models: fitted models by kind, in report order.
        metrics: per kind, its metrics.json entry (rmse_nm, rmse_normalised, timings, history).
        predictions: per kind, (N_eval, n) predictions through the label filter on ``rows``
            [N*m] (``evaluation.scoring``); computed when absent.
        noise_floor: (n,) the label-noise floor on ``rows`` [N*m], where known.
        study_table: the study's Table 1 to place beside ours (``evaluation.study``), if given.
    """

    title: str
    robot: RobotConfig
    dataset: Dataset
    rows: list[tuple[int, int]]
    evaluated_on: str
    target_scale: np.ndarray
    models: dict[str, InverseDynamicsModel]
    metrics: dict[str, dict[str, Any]]
    predictions: dict[str, np.ndarray] = field(default_factory=dict)
    noise_floor: np.ndarray | None = None
    study_table: StudyTable | None = None


def _predictions(report: ReportInput, kinds: list[str]) -> dict[str, np.ndarray]:
    """The given predictions through the label filter, scoring the models that lack them."""
    predictions = dict(report.predictions)
    for kind in kinds:
        if kind not in predictions:
            score = score_model(report.models[kind], report.dataset, report.target_scale)
            predictions[kind] = score.filtered
    return predictions


def _figures(
    report: ReportInput,
    predictions: dict[str, np.ndarray],
    rmse_norm: dict[str, np.ndarray],
    components: dict[str, np.ndarray],
    out: Path,
) -> list[tuple[str, str]]:
    """Write the PNG figures (a)-(d) into ``out``; returns their file names and captions."""
    ds = report.dataset
    joints, kinds = ds.joints, list(report.models)
    figures: list[tuple[str, str]] = []
    if kinds:
        target = ds.tau[_evaluated_index(report)]
        plot_rmse(joints, rmse_norm, out / 'rmse_per_joint.png')
        figures.append(('rmse_per_joint.png', '(a) Test RMSE per joint, normalised scale'))
        plot_boxes(
            joints,
            {k: absolute_errors(predictions[k], target) for k in kinds},
            out / 'abs_error_boxplot.png',
        )
        figures.append(('abs_error_boxplot.png', '(b) Absolute test errors per joint and model'))
    if kinds and not ds.is_shuffled:  # a shuffled split's test samples form no stretch
        dissipative_figure(
            robot=report.robot,
            dataset=ds,
            rows=report.rows,
            models=report.models,
            predictions=predictions,
            path=out / 'dissipative_axis1.png',
        )
        figures.append(
            ('dissipative_axis1.png', f'(c) Dissipative torque on {joints[0]}, test stretch')
        )
    plot_shares(joints, torque_splits(ds, components, report.models), out / 'torque_shares.png')
    figures.append(('torque_shares.png', '(d) Share of the label torque per joint'))
    return figures


def _evaluated_index(report: ReportInput) -> np.ndarray:
    """The evaluated rows of the dataset, in order."""
    return np.concatenate([np.arange(a, b) for a, b in report.rows])


def _header(report: ReportInput) -> list[str]:
    """The title and what was evaluated: robot, labels, filter, data and fitting mode."""
    ds, robot = report.dataset, report.robot
    n = len(_evaluated_index(report))
    label = 'tau_u from motor currents' if ds.target == 'motor' else 'measured joint torque'
    return [
        f'# {report.title}',
        '',
        f'Robot {robot.name}, joints {", ".join(ds.joints)}. Labels: {label}, low-passed at '
        f'{fmt(ds.cutoff_hz)} Hz (zero-phase Butterworth, order {ds.filter_order}). Evaluated '
        f'on {report.evaluated_on} ({n} samples, {n * ds.period_s:.0f} s). '
        f'Models fitted {MODES[ds.mode]}.',
        '',
    ]


def _figures_section(figures: list[tuple[str, str]]) -> list[str]:
    lines = ['## Figures', '']
    for name, caption in figures:
        lines += [f'### {caption}', '', f'![{caption}]({name})', '']
    return lines


def _study_table_findings(
    table: StudyTable | None, joints: tuple[str, ...], share: np.ndarray
) -> list[Finding] | None:
    """The motor-label findings decided on the study's own Table 1 (motor-current labels).

    Its high-friction axes are taken from this recording's friction share (same robot class):
    the table has no data to decide them from.
    """
    if table is None or len(table.joints) != len(joints):
        return None
    errors = {kind: np.asarray(row) for kind, row in table.rmse_normalised.items()}
    return check_findings('motor', joints, errors, share)


def write_report(report: ReportInput, out: Path) -> tuple[Path, list[dict[str, Any]]]:
    """Write ``report.md`` and its PNG figures into ``out``.

    Returns:
        The report's path and the checked findings (JSON-ready).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ds, metrics = report.dataset, report.metrics
    kinds = list(report.models)
    predictions = _predictions(report, kinds)
    rmse_norm = {k: np.asarray(metrics[k]['rmse_normalised']) for k in kinds}
    stopped_by = {k: _stopped_by(metrics[k].get('history') or {}) for k in kinds}

    components = nominal_components(ds, report.robot)
    share = friction_share(ds.tau, components['remainder'], ds.study.v)
    findings = check_findings(ds.target, ds.joints, rmse_norm, share, stopped_by)
    on_table = _study_table_findings(report.study_table, ds.joints, share)
    figures = _figures(report, predictions, rmse_norm, components, out)

    study_way = {k: np.asarray(metrics[k]['study_way']['rmse_normalised']) for k in kinds}
    lines = [
        *_header(report),
        *accuracy_tables(ds, metrics, kinds, report.noise_floor, report.target_scale),
        *identified_physics_section(report.models, report.robot),
        "### The study's Table 1",
        '',
        study_table(kinds, study_way, ds.joints, report.study_table),
        '',
        '## Training and inference time',
        '',
        timing_table(metrics, kinds, stopped_by),
        '',
        *findings_section(findings, ds.target, on_table),
        *_figures_section(figures),
    ]
    path = out / 'report.md'
    write_text_atomic(path, '\n'.join(lines))  # whole or absent, even on a full disk
    return path, [f.to_dict() for f in findings]


def _stopped_by(history: dict[str, Any]) -> str | None:
    """Why a network's fit stopped, and whether it ever improved on the validation part."""
    reason = history.get('stopped_by')
    if reason is not None and history.get('never_improved'):
        return f'{reason}; no validation gain after epoch 0'
    return reason
