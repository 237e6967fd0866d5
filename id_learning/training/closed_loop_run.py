"""``closed-loop``: a training run's models as feed-forward in the twin's loop, side by side.

The reference is the test part of the run's first training bag (its last share in time), as a
controller sends it (``Dataset.controller``); the plant is the twin robot that bag was recorded
from (the ``twin_config.yaml`` the twin wrote beside it, or ``twin_config``). Writes
closed_loop.json (per run and joint the RMS and largest tracking error, and
``improvement_best``) and closed_loop.png (the tracking errors over time).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.errors import CheckpointError, ConfigError
from id_learning.evaluation.closed_loop import (
    FEEDBACK_ONLY,
    TRUE_DYNAMICS,
    Tracking,
    compare_feed_forward,
    improvement,
    reference_gains,
)
from id_learning.models.registry import load_model
from id_learning.outputs import check_output, result_folder
from id_learning.robot.config import RobotConfig
from id_learning.training.datasets import load_datasets, preprocess_from_dict, segment_rows
from id_learning.training.run_folder import MODELS_DIR, read_run, training_bag
from id_learning.twin import load_twin_config
from id_learning.twin.plant import TwinPlant
from id_learning.twin.simulate import TWIN_CONFIG_COPY

__all__ = ['CLOSED_LOOP_JSON', 'ClosedLoopResult', 'closed_loop_run']

CLOSED_LOOP_JSON = 'closed_loop.json'
CLOSED_LOOP_PNG = 'closed_loop.png'


@dataclass(frozen=True)
class ClosedLoopResult:
    """What ``closed_loop_run`` measured and wrote."""

    runs: dict[str, Tracking]
    best_model: str
    improvement_best: np.ndarray
    document: dict[str, Any]
    json_path: Path
    plot_path: Path

    def summary(self) -> str:
        """The RMS tracking error per run and joint [mrad], and the improvement, as a table."""
        joints = self.document['joints']
        width = max(len(name) for name in self.runs) + 2
        lines = [f'{"RMS tracking error [mrad]":<{width}}' + ''.join(f'{j:>10}' for j in joints)]
        for name, run in self.runs.items():
            lines.append(f'{name:<{width}}' + ''.join(f'{1e3 * x:>10.3f}' for x in run.rms))
        lines.append(
            f'{"improvement (" + self.best_model + ")":<{width}}'
            + ''.join(f'{x:>10.1f}' for x in self.improvement_best)
        )
        return '\n'.join(lines)


def _twin_config_path(bag: Path, twin_config: Path | None) -> Path:
    """The plant's config: the one given, else the twin's copy beside the reference's bag."""
    if twin_config is not None:
        return Path(twin_config)
    if (bag / TWIN_CONFIG_COPY).is_file():
        return bag / TWIN_CONFIG_COPY
    raise ConfigError(
        f"no {TWIN_CONFIG_COPY} beside {bag}, the run's first training bag: the closed loop "
        'needs the twin robot the data came from; pass --twin CONFIG'
    )


def closed_loop_run(
    run_dir: Path,
    robot: RobotConfig,
    out: Path,
    *,
    twin_config: Path | None = None,
    duration_s: float = 60.0,
    kinds: Sequence[str] | None = None,
    progress: bool = True,
    force: bool = False,
    run_name: Path | None = None,
) -> ClosedLoopResult:
    """Track the run's test motion on the twin with each model's feed-forward; write the results.

    ``out`` is written whole or not at all (``id_learning.outputs``); ``force`` replaces an
    earlier result there, never the run itself. ``run_name``: the run's path as closed_loop.json
    records it, where ``run_dir`` is read inside another command's partial folder (the demo's).

    Raises:
        CheckpointError: the run is incomplete, or it or a model does not fit the robot.
        ConfigError: no twin config, one of another robot, or a model the run lacks.
        OutputError: ``out`` is refused, or a write failed.
    """
    run_dir, out = Path(run_dir), Path(out)
    if not duration_s > 0:
        raise ConfigError(f'duration must be positive [s], got {duration_s}')
    run = read_run(run_dir)
    check_output(out, force=force, inputs=[run_dir], kind='closed-loop')  # before the loop
    if run.get('robot', {}).get('joints') != list(robot.joints):
        raise CheckpointError(f'{run_dir}: the run is not for robot {robot.name}')
    bag = training_bag(run, run_dir)
    twin_path = _twin_config_path(bag, twin_config)
    twin = load_twin_config(twin_path)
    if twin.robot.name != robot.name or twin.robot.joints != robot.joints:
        raise ConfigError(
            f'{twin_path}: twin robot {twin.robot.name} is not robot {robot.name} of the run'
        )
    kinds = list(kinds or run['kinds'])
    unknown = sorted(set(kinds) - set(run['kinds']))
    if unknown:
        raise ConfigError(f'{run_dir}: no model(s) {unknown} in the run; it has {run["kinds"]}')
    config = preprocess_from_dict(run['preprocessing'])
    dataset = load_datasets([bag], robot, config, progress=False)[0]
    if dataset.is_shuffled:  # its test samples are scattered: the last share in time
        start, end = round(config.train_fraction * len(dataset.q)), len(dataset.q)
        part = 'the last share in time (a shuffled split: it holds training samples too)'
    else:
        start, end = segment_rows(dataset, 'test')[0]
        part = 'the test part'
    stop = min(end, start + round(duration_s / robot.ipo_period_s))
    if stop - start < 2:
        raise ConfigError(f'{bag}: {stop - start} samples of the test part to track')
    reference = dataset.controller.take(slice(start, stop))
    # The plant's friction warms up from where the reference starts in the recording.
    offset_s = float(dataset.stamps_ns[start] - dataset.stamps_ns[0]) * 1e-9
    plant = TwinPlant(replace(twin, shift_start_s=twin.shift_start_s + offset_s))
    feed_forward = {
        kind: load_model(run_dir / MODELS_DIR / kind, robot, kind).predict(
            reference.q, reference.v, reference.a
        )
        for kind in kinds
    }
    feed_forward[TRUE_DYNAMICS] = (
        plant.motor_torque(reference.q + plant.encoder_offset, reference.v, reference.a)
        / plant.kt_scale
    )
    gains = reference_gains(plant, reference)
    runs = compare_feed_forward(
        plant, reference, feed_forward, period_s=robot.ipo_period_s, gains=gains, progress=progress
    )
    best, ratio = improvement(runs, kinds)
    document = {
        'run': str(run_name or run_dir),
        'twin_config': str(twin_path),
        'reference': {
            'bag': str(bag),
            'rows': [start, stop],
            'duration_s': (stop - start) * robot.ipo_period_s,
            'part': part,
        },
        'joints': list(robot.joints),
        'controller': {
            'structure': 'position P, velocity PI, torque limit, at the IPO period',
            'period_s': robot.ipo_period_s,
            'position_gain_per_s': gains.position.tolist(),
            'velocity_gain_nms_per_rad': gains.velocity.tolist(),
            'integral_gain_nm_per_rad': gains.integral.tolist(),
        },
        'runs': {
            name: {
                # None for a loop that diverged (JSON has no infinity).
                'rms_rad': None if track.diverged_at is not None else track.rms.tolist(),
                'max_rad': None if track.diverged_at is not None else track.max.tolist(),
                'saturated_cycles': track.saturated.tolist(),
                'diverged_at_cycle': track.diverged_at,
            }
            for name, track in runs.items()
        },
        'best_model': best,
        'improvement_best': ratio.tolist(),
    }
    with result_folder(out, command='closed-loop', force=force, inputs=[run_dir]) as folder:
        (folder.work / CLOSED_LOOP_JSON).write_text(
            json.dumps(document, indent=2), encoding='utf-8'
        )
        _plot(runs, best, robot, folder.work / CLOSED_LOOP_PNG)
    out = folder.out
    return ClosedLoopResult(
        runs, best, ratio, document, out / CLOSED_LOOP_JSON, out / CLOSED_LOOP_PNG
    )


def _plot(runs: dict[str, Tracking], best: str, robot: RobotConfig, path: Path) -> Path:
    """Tracking error over time per joint: feedback alone, the best model, true dynamics."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = robot.n_joints
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.6 * n), sharex=True)
    t = np.arange(len(runs[FEEDBACK_ONLY].error)) * robot.ipo_period_s
    for j, ax in enumerate(np.atleast_1d(axes)):
        for name in (FEEDBACK_ONLY, best, TRUE_DYNAMICS):
            ax.plot(t, 1e3 * runs[name].error[:, j], lw=0.7, label=name)
        ax.set_ylabel(f'{robot.joints[j]}\n[mrad]', fontsize=8)
    np.atleast_1d(axes)[0].legend(fontsize=7, loc='upper right')
    np.atleast_1d(axes)[-1].set_xlabel('time [s]')
    fig.suptitle("Tracking error in the twin's loop (reference minus true position)")
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path
