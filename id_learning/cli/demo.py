"""The ``demo`` subcommand: the main job on a bag, end to end.

In order: a data summary with plots; the diagnosis (``--skip-diagnosis`` skips it); the training
of ``--models`` (default ``DEMO_MODELS``: the study's seven, the identified physics and the
diagnosed model, nine kinds) with a report; the closed loop on the twin, feedback alone and with
each model as feed-forward (the twin config beside the bag, or ``--twin``; a bag of a real
robot without one skips it, saying so); the online check: a stretch
of the test part replayed in real time through the predictor node with the best model (skipped
without rclpy). ``--skip-training`` stops after the diagnosis. It composes the other commands'
work (``diagnose_bags``, ``metrics_table``, ``closed_loop_run``), so it sits on top of their
modules; the closed loop and the online check are imported only when they run.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from id_learning.cli import options
from id_learning.cli.diagnose import diagnose_bags
from id_learning.cli.paths import default_bag, default_robot_config
from id_learning.cli.train import metrics_table
from id_learning.errors import DatasetError

__all__ = ['DEMO_MODELS', 'DEMO_SECONDS_PER_MODEL', 'add_demo_command', 'cmd_demo']

#: The demo trains the study's seven, the identified physics and the diagnosed model (nine).
DEMO_MODELS = 'study,rnea_id,rnea_effects'
#: The identification's and the diagnosis's budget in the demo [s], whatever --train-seconds
#: gives the networks: on the shipped 10 min bag they take about 20 and 50 s of CPU, and the
#: demo is where a user first reads them.
DEMO_PHYSICS_SECONDS = 300.0
#: Budget per model in ``demo``: nine models on the shipped bag within 10 minutes on 2 cores.
DEMO_SECONDS_PER_MODEL = 60.0
#: The defaults of the options that default to None, so that --skip-training can refuse them.
_SECONDS_DEFAULTS = {
    'train_seconds': DEMO_SECONDS_PER_MODEL,
    'online_seconds': 30.0,
    'closed_loop_seconds': 60.0,
    'models': DEMO_MODELS,
}


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job on a bag: load, preprocess, summarise with plots, diagnose, train, check.

    OUT is written whole or not at all: into OUT.partial, renamed when complete
    (``id_learning.outputs``); --force replaces an earlier demo there.
    """
    from id_learning.outputs import result_folder

    options.refuse_contradictions(
        args,
        [
            (option, '--skip-training', 'nothing is trained')
            for option in (
                '--models',
                '--train-seconds',
                '--online-seconds',
                '--closed-loop-seconds',
                '--study-table',
                '--twin',
            )
        ]
        + [('--twin', '--closed-loop-seconds=0.0', 'the closed loop is skipped')],
    )
    for key, default in _SECONDS_DEFAULTS.items():  # None marks an option not given
        if getattr(args, key) is None:
            setattr(args, key, default)
    robot = options.load_robot(args)
    options.model_kinds(args.models)  # unknown kinds refused even with --skip-training
    if args.twin:  # refused before the work, not after the training
        _check_twin(Path(args.twin), robot)
    args.study_table = options.study_table(args, robot)  # read once, before the work
    bag = Path(args.bag or default_bag())
    inputs = [bag, *([Path(args.twin)] if args.twin else [])]
    with result_folder(Path(args.out), command='demo', force=args.force, inputs=inputs) as folder:
        _demo_into(args, robot, bag, folder)
    return 0


def _check_twin(path: Path, robot: Any) -> None:
    """Refuse a ``--twin`` that cannot be the plant: unreadable, or of another robot.

    Raises:
        ConfigError: names --twin, the file and why.
    """
    from id_learning.errors import ConfigError
    from id_learning.robot.config import how_robots_differ
    from id_learning.twin import load_twin_config

    try:
        twin = load_twin_config(path)
    except ConfigError as err:
        raise ConfigError(f'--twin {path}: {err}') from err
    difference = how_robots_differ(robot, twin.robot)
    if difference:
        raise ConfigError(
            f"--twin {path}: the twin is not the demo's robot (--robot): it has {difference}"
        )


def _demo_into(args: argparse.Namespace, robot: Any, bag: Path, folder: Any) -> None:
    """The demo's steps, written into ``folder.work``; paths are shown as they will be."""
    from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
    from id_learning.dataset.recording import load_recording
    from id_learning.evaluation.data_summary import write_summary
    from id_learning.physics.rigid_body import RigidBodyDynamics

    out, shown = folder.work, folder.out
    print(f'loading {bag} ...', flush=True)
    recording = load_recording(
        bag,
        robot,
        require_current=args.target == 'motor',
        progress=True,
        gravity=RigidBodyDynamics.from_config(robot).gravity,
    )
    if len(recording.segment_starts) > 1:
        raise DatasetError(
            f'{bag}: holds {len(recording.segment_starts)} segments; the demo summarises one '
            'recording: run train and diagnose on it instead'
        )
    preprocess = PreprocessConfig(target=args.target, mode=args.preprocessing)
    dataset = prepare_dataset(recording, robot, preprocess)
    from id_learning.twin.ground_truth import read_ground_truth

    # A damaged one, or one of another simulation, is refused naming the file.
    truth = read_ground_truth(bag, args.target, recording.stamps_ns)
    ground_truth, tau_clean = (truth.info, truth.tau_clean) if truth else (None, None)
    summary = write_summary(dataset, robot, out, ground_truth=ground_truth, tau_clean=tau_clean)
    print(
        f'{summary.n_samples} samples, {summary.duration_s:.0f} s; '
        f'summary written to {shown / "summary.md"}',
        flush=True,
    )
    if not args.skip_diagnosis:
        _demo_diagnosis(
            bag, robot, preprocess, recording, out / 'diagnosis', shown=shown / 'diagnosis'
        )
    if args.skip_training:
        return
    from id_learning.training import train_run

    kinds = options.model_kinds(args.models)
    print(
        f'training {len(kinds)} models ({", ".join(kinds)}), at most '
        f'{args.train_seconds:g} s each ...',
        flush=True,
    )
    physics = max(args.train_seconds, DEMO_PHYSICS_SECONDS)
    folder.keep = True  # from here on it holds fitted models
    run = train_run(
        [bag],
        robot,
        args.target,
        kinds,
        out / 'run',
        hyper={k: {'max_seconds': physics} for k in ('rnea_id', 'rnea_effects') if k in kinds},
        max_seconds_per_model=args.train_seconds,
        device=args.device,
        preprocess=preprocess,
        study_table=args.study_table,
    )
    print(metrics_table(run.metrics))
    print(f'report: {shown / "run" / "report.md"}', flush=True)
    for kind, why in run.failures.items():
        print(f'{kind} failed (the other models go on): {why}', flush=True)
    if args.closed_loop_seconds > 0:
        _demo_closed_loop(args, robot, run, out, shown)
    if args.online_seconds > 0:
        _demo_online_check(args, bag, run, out)


def _demo_closed_loop(
    args: argparse.Namespace, robot: Any, run: Any, out: Path, shown: Path
) -> None:
    """Track the test motion on the twin with each model as feed-forward.

    The plant is ``--twin``, else the twin config beside the bag; a bag of a real robot (no twin
    config beside it, none given) skips this step.
    """
    from id_learning.errors import ConfigError
    from id_learning.training.closed_loop_run import closed_loop_run

    print(
        f'closed loop: tracking {args.closed_loop_seconds:g} s of the test part on the twin, '
        'feedback alone and with each model as feed-forward ...',
        flush=True,
    )
    try:
        result = closed_loop_run(
            run.out,
            robot,
            out / 'closed_loop',
            twin_config=Path(args.twin) if args.twin else None,
            duration_s=args.closed_loop_seconds,
            run_name=shown / 'run',
            report=run.out / 'report.md',
        )
    except ConfigError as err:
        print(f'closed loop not run: {err}', flush=True)
        return
    print(result.summary())
    print(
        f'closed loop: {shown / "closed_loop" / result.json_path.name}; plots: '
        f'{shown / "closed_loop" / result.plot_path.name}, '
        f'{shown / "closed_loop" / result.feed_forward_plot_path.name}; section (h) of '
        f'{shown / "run" / "report.md"}',
        flush=True,
    )


def _demo_diagnosis(
    bag: Path, robot: Any, preprocess: Any, recording: Any, out: Path, *, shown: Path
) -> None:
    """Diagnose the loaded bag into ``out``; a bag it cannot diagnose only skips this step.

    ``shown``: where ``out`` will be once the demo is complete (for the paths printed).
    """
    from id_learning.diagnosis.report import render_summary

    try:
        result = diagnose_bags(
            [bag],
            robot,
            preprocess,
            out,
            progress=False,
            recordings=[recording],
            final=shown,
        )
    except DatasetError as err:  # e.g. too short: the rest of the demo still runs
        print(f'diagnosis not run: {err}', flush=True)
    else:
        print(render_summary(result))
        print(
            f'diagnosis report: {shown / "report.md"}; waterfall plot: {shown / "waterfall.png"}',
            flush=True,
        )


def _demo_online_check(args: argparse.Namespace, bag: Path, run: Any, out: Path) -> None:
    """Replay the test part's start through the predictor node with the run's best model."""
    from id_learning.online_check import has_ros, online_check

    if not has_ros():
        print('online check not run: rclpy (ROS 2 Jazzy) is not installed', flush=True)
        return
    models = run.metrics['models']
    kind = min(models, key=lambda k: models[k]['mean_rmse_normalised'])
    print(
        f'online check: replaying {args.online_seconds:g} s of the test part in real time '
        f'through the predictor node with the best model ({kind}) ...',
        flush=True,
    )
    check = online_check(
        bag,
        Path(args.robot or default_robot_config()),
        run.models[kind].folder,
        seconds=args.online_seconds,
        out=out / 'online_check.json',
    )
    print(check.summary(), flush=True)


def add_demo_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``demo`` to the subcommands ``sub``."""
    p = sub.add_parser(
        'demo',
        help='the main job on a bag: data summary, diagnosis, training (default: nine model '
        'kinds) with a report, closed loop on the twin, online check of the best model',
    )
    p.add_argument('--bag', help='bag folder (default: the shipped bags/default)')
    p.add_argument('--out', default='out/demo', help='output folder (the run goes to OUT/run)')
    p.add_argument(
        '--force',
        action='store_true',
        help='replace an earlier demo (or an interrupted one) in OUT',
    )
    options.target_option(p)
    options.preprocessing_option(p)
    p.add_argument(
        '--models',
        help=f'comma-separated model kinds to train (default: {DEMO_MODELS})',
    )
    p.add_argument(
        '--train-seconds',
        type=options.fit_seconds,
        help=f'wall-clock budget per model fit [s] (default {DEMO_SECONDS_PER_MODEL:g}); the '
        f'identification and the diagnosis get at least {DEMO_PHYSICS_SECONDS:g} s',
    )
    p.add_argument(
        '--skip-training',
        action='store_true',
        help='stop after the data summary and the diagnosis: no training, closed loop or online '
        'check',
    )
    p.add_argument('--skip-diagnosis', action='store_true', help='do not run the diagnosis')
    p.add_argument(
        '--online-seconds',
        type=options.finite(0.0, 86400.0),
        help='seconds of the test part replayed through the predictor node (default 30; 0: skip)',
    )
    p.add_argument(
        '--closed-loop-seconds',
        type=options.finite(0.0, 86400.0),
        help="seconds of the test part tracked in the twin's closed loop (default 60; 0: skip)",
    )
    p.add_argument(
        '--twin',
        metavar='CONFIG',
        help="twin config of the closed loop's plant (default: the twin_config.yaml beside the "
        'bag; a bag of a real robot has none, and the closed loop is skipped without one)',
    )
    p.add_argument('--device', choices=('auto', 'cpu', 'cuda'), default='auto')
    options.study_table_option(p)
    options.robot_option(p)
    p.set_defaults(func=cmd_demo)
