"""``closed-loop``: a training run's models as feed-forward in the twin's loop, side by side.

The reference is the test part of the run's first training bag (its last share in time), as a
controller sends it (``Dataset.controller``); the plant is the twin robot that bag was recorded
from (the ``twin_config.yaml`` the twin wrote beside it, or ``twin_config``). Writes
closed_loop.json (per run and joint the RMS and largest tracking error, and
``improvement_best``), closed_loop.png (the tracking errors over time),
closed_loop_feed_forward.png (the feed-forwards against the torque limits) and report.md (the
section ``evaluation.closed_loop_report`` writes; it is added to a run's report when given one).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.inputs import Motion
from id_learning.dataset.preprocess import Dataset, PreprocessConfig
from id_learning.errors import CheckpointError, ConfigError
from id_learning.evaluation.closed_loop import (
    TRUE_DYNAMICS,
    Tracking,
    compare_feed_forward,
    improvement,
    reference_gains,
)
from id_learning.evaluation.closed_loop_report import (
    RMS_WINDOW_S,
    add_section,
    closed_loop_section,
    plot_feed_forward,
    plot_tracking,
)
from id_learning.outputs import check_output, result_folder
from id_learning.robot.config import RobotConfig, how_robots_differ
from id_learning.training.datasets import load_datasets, preprocess_from_dict, segment_rows
from id_learning.training.run_folder import (
    is_training_bag,
    load_run_model,
    read_run,
    refuse_training_samples,
    training_bag,
)
from id_learning.training.run_identity import RUN_IDENTITY_KEY, check_run_unchanged, run_identity
from id_learning.twin import load_twin_config
from id_learning.twin.plant import TwinPlant
from id_learning.twin.simulate import TWIN_CONFIG_COPY, TwinConfig

__all__ = ['CLOSED_LOOP_JSON', 'DEFAULT_DURATION_S', 'ClosedLoopResult', 'closed_loop_run']

_LOG = logging.getLogger(__name__)

CLOSED_LOOP_JSON = 'closed_loop.json'
CLOSED_LOOP_PNG = 'closed_loop.png'
FEED_FORWARD_PNG = 'closed_loop_feed_forward.png'
#: The closed-loop section on its own, beside the results.
CLOSED_LOOP_MD = 'report.md'
#: Seconds of the test part tracked when no duration is asked for (the whole part if shorter).
DEFAULT_DURATION_S = 60.0


@dataclass(frozen=True)
class ClosedLoopResult:
    """What ``closed_loop_run`` measured and wrote."""

    runs: dict[str, Tracking]
    best_model: str
    improvement_best: np.ndarray
    document: dict[str, Any]
    json_path: Path
    plot_path: Path
    feed_forward_plot_path: Path
    report_path: Path

    def summary(self) -> str:
        """The RMS tracking error per run and joint [mrad], and the improvement, as a table."""
        joints = self.document['joints']
        head, gain = 'RMS tracking error [mrad]', f'improvement ({self.best_model})'
        width = max(len(name) for name in (*self.runs, head, gain)) + 2
        column = max(10, *(len(joint) + 2 for joint in joints))  # names never run together
        lines = [f'{head:<{width}}' + ''.join(f'{j:>{column}}' for j in joints)]
        for name, run in self.runs.items():
            lines.append(f'{name:<{width}}' + ''.join(f'{1e3 * x:>{column}.3f}' for x in run.rms))
        lines.append(
            f'{gain:<{width}}' + ''.join(f'{x:>{column}.1f}' for x in self.improvement_best)
        )
        reference = self.document['reference']
        asked = reference.get('requested_duration_s')
        cut = f', not the {asked:g} s asked for' if reference.get('shortened') else ''
        lines.append(
            f'tracked {reference["duration_s"]:.2f} s{cut}: {reference["part"]} of '
            f'{reference["bag"]} (it holds {reference["available_s"]:.2f} s)'
        )
        return '\n'.join(lines)


def _reference_bag(
    run: dict[str, Any], run_dir: Path, robot: RobotConfig, bag: Path | None
) -> tuple[Path, bool]:
    """The bag to track, and whether the run was not trained on it (``closed_loop_run``'s bag).

    Raises:
        DatasetError: ``bag`` is no training bag but holds samples of one.
    """
    if bag is None:
        return training_bag(run, run_dir), False
    if is_training_bag(Path(bag), run):
        return Path(bag), False
    refuse_training_samples([Path(bag)], run, run_dir, robot)
    return Path(bag), True


def _plant_config(
    bag: Path, twin_config: Path | None, robot: RobotConfig
) -> tuple[Path, TwinConfig]:
    """The plant's twin config (``_twin_config_path``) and the config read.

    Raises:
        ConfigError: no twin config, or one of another robot.
    """
    twin_path = _twin_config_path(bag, twin_config)
    twin = load_twin_config(twin_path)
    difference = how_robots_differ(robot, twin.robot)
    if difference:
        raise ConfigError(f"{twin_path}: the twin is not the run's robot: it has {difference}")
    return twin_path, twin


def _run_kinds(run: dict[str, Any], run_dir: Path, kinds: Sequence[str] | None) -> list[str]:
    """The kinds asked for (None: all of the run's); one the run lacks is refused."""
    chosen = list(run['kinds'] if kinds is None else kinds)
    unknown = sorted(set(chosen) - set(run['kinds']))
    if unknown:
        raise ConfigError(f'{run_dir}: no model(s) {unknown} in the run; it has {run["kinds"]}')
    return chosen


def _twin_config_path(bag: Path, twin_config: Path | None) -> Path:
    """The plant's config: the one given, else the twin's copy beside the reference's bag."""
    if twin_config is not None:
        return Path(twin_config)
    if (bag / TWIN_CONFIG_COPY).is_file():
        return bag / TWIN_CONFIG_COPY
    raise ConfigError(
        f'no {TWIN_CONFIG_COPY} beside {bag}, the bag the reference is taken from (a recording '
        'the twin did not write?): the closed loop needs the twin robot the data came from; '
        'pass --twin CONFIG'
    )


def _reference_rows(
    dataset: Dataset, config: PreprocessConfig, samples: int, unseen: bool = False
) -> tuple[int, int, int, str]:
    """The reference's rows [start, stop) (at most ``samples``), its part's end, and the part.

    ``unseen``: a recording the run was not trained on, tracked from its start (its first
    segment).
    """
    if unseen:  # the whole of its first segment: no part of it was trained on
        start, end = 0, len(dataset.q)
        part = 'a recording the run was not trained on, from its start'
    elif dataset.is_shuffled:  # its test samples are scattered: the last share in time
        start, end = round(config.train_fraction * len(dataset.q)), len(dataset.q)
        part = 'the last share in time (a shuffled split: it holds training samples too)'
    else:
        start, end = segment_rows(dataset, 'test')[0]
        part = 'the test part'
    return start, min(end, start + samples), end, part


def _tracked(
    dataset: Dataset,
    config: PreprocessConfig,
    bag: Path,
    period_s: float,
    asked: float | None,
    *,
    unseen: bool = False,
) -> dict[str, Any]:
    """What the reference tracks (closed_loop.json's ``reference``), ``asked`` seconds of it.

    A part shorter than ``asked`` is tracked whole, with a warning naming both (None asks for
    the whole part, at most ``DEFAULT_DURATION_S``, without one).

    Raises:
        ConfigError: fewer than 2 samples to track.
    """
    seconds = DEFAULT_DURATION_S if asked is None else asked
    start, stop, end, part = _reference_rows(dataset, config, round(seconds / period_s), unseen)
    if stop - start < 2:
        if asked is not None and round(asked / period_s) < 2:
            raise ConfigError(
                f'--duration {asked:g} s is shorter than two IPO periods '
                f'({2 * period_s:g} s): nothing to track'
            )
        raise ConfigError(f'{bag}: {stop - start} samples of {part} to track')
    available = (end - start) * period_s
    shortened = asked is not None and stop == end and asked > available + period_s
    if shortened:
        _LOG.warning(
            'duration %g s asked for, but %s of %s holds %.2f s: tracking those %.2f s '
            '(closed_loop.json records both)', asked, part, bag, available, available,
        )  # fmt: skip
    return {
        'bag': str(bag),
        'rows': [start, stop],
        'duration_s': (stop - start) * period_s,
        'requested_duration_s': asked,
        'available_s': available,
        'shortened': shortened,
        'part': part,
    }


def closed_loop_run(
    run_dir: Path,
    robot: RobotConfig,
    out: Path,
    *,
    twin_config: Path | None = None,
    duration_s: float | None = None,
    kinds: Sequence[str] | None = None,
    progress: bool = True,
    force: bool = False,
    run_name: Path | None = None,
    report: Path | None = None,
    bag: Path | None = None,
) -> ClosedLoopResult:
    """Track the run's test motion on the twin with each model's feed-forward; write the results.

    ``duration_s``: seconds of the test part to track; a part shorter than that is tracked whole,
    with a warning naming both (closed_loop.json records both, and ``shortened``). None: the
    whole part, at most ``DEFAULT_DURATION_S``, without a warning.
    ``kinds``: the models to run (None: every model of the run; an empty list is refused).
    ``out`` is written whole or not at all (``id_learning.outputs``); ``force`` replaces an
    earlier result there, never the run itself. ``run_name``: the run's path as closed_loop.json
    records it, where ``run_dir`` is read inside another command's partial folder (the demo's).
    ``report``: a report.md to add the closed-loop section to once ``out`` is complete (the
    demo's run report, inside its own partial folder), its links pointing into ``out``.
    ``bag``: a recording of the twin to track instead of the run's test part: from its start
    when the run was not trained on it (one that holds training samples is refused), its test
    part when it is one of the run's training bags; its twin config is the plant's.
    closed_loop.json records the run's identity beside its path (``run_identity``).

    Raises:
        CheckpointError: the run is incomplete, or it or a model does not fit the robot, or the
            run was replaced while the loop ran (nothing written).
        ConfigError: no twin config, one of another robot, or a model the run lacks.
        DatasetError: ``bag`` holds samples of a training bag.
        OutputError: ``out`` is refused, or a write failed.
    """
    run_dir, out = Path(run_dir), Path(out)
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f'duration must be positive [s], got {duration_s}')
    if kinds is not None and not kinds:
        raise ConfigError('no model kind named: name some, or leave the kinds out for all')
    run = read_run(run_dir)
    inputs = [run_dir, *([Path(bag)] if bag is not None else [])]
    check_output(out, force=force, inputs=inputs, kind='closed-loop')  # before the loop
    if run.get('robot', {}).get('joints') != list(robot.joints):
        raise CheckpointError(f'{run_dir}: the run is not for robot {robot.name}')
    bag, unseen = _reference_bag(run, run_dir, robot, bag)
    twin_path, twin = _plant_config(bag, twin_config, robot)
    kinds = _run_kinds(run, run_dir, kinds)
    config = preprocess_from_dict(run['preprocessing'])
    dataset = load_datasets([bag], robot, config, progress=False)[0]
    tracked = _tracked(dataset, config, bag, robot.ipo_period_s, duration_s, unseen=unseen)
    start, stop = tracked['rows']
    reference = dataset.controller.take(slice(start, stop))
    # The plant's friction warms up from where the reference starts in the recording.
    offset_s = float(dataset.stamps_ns[start] - dataset.stamps_ns[0]) * 1e-9
    plant = TwinPlant(replace(twin, shift_start_s=twin.shift_start_s + offset_s))
    identity, feed_forward = _feed_forwards(run_dir, run, kinds, robot, reference)
    feed_forward[TRUE_DYNAMICS] = plant.command(
        reference.q + plant.encoder_offset, reference.v, reference.a
    )
    gains = reference_gains(plant, reference)
    runs = compare_feed_forward(
        plant, reference, feed_forward, period_s=robot.ipo_period_s, gains=gains, progress=progress
    )
    best, ratio = improvement(runs, kinds)
    document = {
        'run': str(run_name or run_dir),
        RUN_IDENTITY_KEY: identity,  # the path may hold another run later
        'twin_config': str(twin_path),
        'reference': tracked,
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
        _write(
            folder.work,
            document,
            runs=runs,
            feed_forward=feed_forward,
            limits=plant.robot.limits.torque,
            robot=robot,
        )
        check_run_unchanged(run_dir, identity, 'closed-loop')  # not in place before it passes
    out = folder.out
    if report is not None:
        add_section(report, _section(document), out)
    return ClosedLoopResult(
        runs,
        best,
        ratio,
        document,
        out / CLOSED_LOOP_JSON,
        out / CLOSED_LOOP_PNG,
        out / FEED_FORWARD_PNG,
        out / CLOSED_LOOP_MD,
    )


def _feed_forwards(
    run_dir: Path, run: dict[str, Any], kinds: list[str], robot: RobotConfig, reference: Motion
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The run's identity (``run_identity``, taken first); each model's tau_u on ``reference``."""
    identity = run_identity(run_dir, run, kinds)
    feed_forward = {
        kind: load_run_model(run_dir, run, kind, robot)
        .for_the_drive()
        .predict(reference.q, reference.v, reference.a)
        for kind in kinds
    }
    return identity, feed_forward


def _section(document: dict[str, Any]) -> list[str]:
    """The closed-loop section of a report, its figure links relative to the results' folder."""
    seconds = f'{RMS_WINDOW_S:g} s'
    figures = [
        (
            CLOSED_LOOP_PNG,
            'Tracking error over time per joint',
            f'The moving RMS ({seconds}) of the tracking error of every run on a log scale: '
            'feedback alone wide and grey, the true inverse dynamics dashed black on top, each '
            'model in its colour and line style (one under the truth shows through its dashes).',
        ),
        (
            FEED_FORWARD_PNG,
            'Feed-forward per joint against the torque limits',
            "Left: each model's feed-forward tau_u along the reference with the true inverse "
            'dynamics, the torque limits in red where they come into reach and ticks at the '
            'cycles where a command sat on them. Right: each feed-forward minus the true one, '
            'what the loop has to correct.',
        ),
    ]
    return closed_loop_section(document, figures)


def _write(
    folder: Path,
    document: dict[str, Any],
    *,
    runs: dict[str, Tracking],
    feed_forward: dict[str, np.ndarray],
    limits: np.ndarray,
    robot: RobotConfig,
) -> None:
    """Write closed_loop.json, the two figures and the section on its own into ``folder``."""
    (folder / CLOSED_LOOP_JSON).write_text(json.dumps(document, indent=2), encoding='utf-8')
    plot_tracking(runs, robot.joints, robot.ipo_period_s, folder / CLOSED_LOOP_PNG)
    plot_feed_forward(
        feed_forward,
        runs,
        limits=limits,
        joints=robot.joints,
        period_s=robot.ipo_period_s,
        path=folder / FEED_FORWARD_PNG,
    )
    lines = [f'# Closed loop of run `{document["run"]}`', '', *_section(document)]
    (folder / CLOSED_LOOP_MD).write_text('\n'.join(lines), encoding='utf-8')
