"""The ``train`` and ``evaluate`` subcommands, and the metrics table they (and ``demo``) print.

``add_train_arguments`` is also the whole parser of the ``train`` console script
(``ros2 run id_learning train``), which ``main.train_main`` runs as ``id-learning train``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from id_learning.cli import options

__all__ = [
    'add_train_arguments',
    'add_train_commands',
    'cmd_evaluate',
    'cmd_train',
    'metrics_table',
]


def metrics_table(metrics: dict[str, Any]) -> str:
    """Per-joint test RMSE through the label filter [N*m], with the floor, as plain text."""
    from id_learning.evaluation.study import MODEL_LABELS

    joints = metrics['joints']
    floor = metrics.get('label_noise_floor_nm')
    width = 24
    # A column as wide as the longest joint name and a space (a Panda's are 12 characters).
    cell = max(10, 1 + max(len(j) for j in joints))

    def row(label: str, values: Sequence[float], last: str = '') -> str:
        return f'{label:<{width}}' + ''.join(f'{x:>{cell}.3g}' for x in values) + last

    head = f'{"test RMSE through filter":<{width}}' + ''.join(f'{j:>{cell}}' for j in joints)
    lines = [head + f'{"mean norm.":>12}']
    for kind, entry in metrics['models'].items():
        label = MODEL_LABELS.get(kind, kind)
        lines.append(row(label, entry['rmse_nm'], f'{entry["mean_rmse_normalised"]:>12.3g}'))
    if floor is not None:
        lines.append(row('label-noise floor', floor))
        lines += [
            '',
            f'{"x label-noise floor":<{width}}' + ''.join(f'{j:>{cell}}' for j in joints),
        ]
        for kind, entry in metrics['models'].items():
            ratio = entry.get('rmse_through_filter_over_floor')
            if ratio is not None:
                lines.append(row(MODEL_LABELS.get(kind, kind), ratio))
    lines += [
        '',
        f'{"study way [N*m]":<{width}}'
        + ''.join(f'{j:>{cell}}' for j in joints)
        + f'{"mean norm.":>12}',
    ]
    for kind, entry in metrics['models'].items():
        study = entry['study_way']
        lines.append(
            row(
                MODEL_LABELS.get(kind, kind),
                study['rmse_nm'],
                f'{study["mean_rmse_normalised"]:>12.3g}',
            )
        )
    return '\n'.join(lines)


def cmd_train(args: argparse.Namespace) -> int:
    """Train models on bags; write models, metrics.json and report.md into the run folder."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.training import train_run

    options.refuse_contradictions(args, [options.SPLIT_SEED_CONTRADICTION])
    hyper = _merged_hyper(args)  # its contradictions refused before anything is read
    robot = options.load_robot(args)
    run = train_run(
        options.bag_paths(args.bag),
        robot,
        args.target,
        options.model_kinds(args.models),
        Path(args.out),
        hyper=hyper,
        max_seconds_per_model=args.max_seconds_per_model,
        progress=not args.quiet,
        device=args.device,
        preprocess=PreprocessConfig(
            mode=args.preprocessing, split=args.split, split_seed=options.split_seed(args)
        ),
        study_table=options.study_table(args, robot),
        overwrite=args.force,
        trim_unpaired_tail=args.trim_unpaired_tail,
        announce=lambda line: print(f'id-learning train: {line}', file=sys.stderr, flush=True),
    )
    print(metrics_table(run.metrics))
    print(f'models: {run.out / "models"}; metrics: {run.metrics_path}; report: {run.report}')
    return _report_failures(run.failures)


def _report_failures(failures: dict[str, str]) -> int:
    """Say which models failed (the others are written); the exit status: 1 if any did."""
    for kind, why in failures.items():
        print(f'id-learning train: {kind} failed (the other models are saved): {why}',
              file=sys.stderr)  # fmt: skip
    return 1 if failures else 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Evaluate every model of a run on other recordings."""
    from id_learning.training import evaluate_run

    run_dir = Path(args.run)
    robot = _run_robot(args, run_dir)
    result = evaluate_run(
        run_dir,
        options.bag_paths(args.bag),
        robot,
        Path(args.out),
        progress=not args.quiet,
        force=args.force,
    )
    print(metrics_table(result.metrics))
    print(f'metrics: {result.out / "metrics.json"}; report: {result.report}')
    return 0


def _run_robot(args: argparse.Namespace, run_dir: Path) -> Any:
    """``--robot``, else the robot config the run was trained with, else the shipped one."""
    if args.robot:
        return options.load_robot(args)
    from id_learning.robot import load_robot_config
    from id_learning.training import read_run

    source = read_run(run_dir).get('robot_config')
    return load_robot_config(source) if source else options.load_robot(args)


def cmd_closed_loop(args: argparse.Namespace) -> int:
    """Track the run's test motion on the twin with each model's tau_u as feed-forward."""
    from id_learning.training.closed_loop_run import closed_loop_run

    run_dir = Path(args.run)
    kinds = None if args.models is None else options.model_kinds(args.models)  # '' is refused
    result = closed_loop_run(
        run_dir,
        _run_robot(args, run_dir),
        Path(args.out),
        twin_config=Path(args.twin) if args.twin else None,
        duration_s=args.duration,
        kinds=kinds,
        progress=not args.quiet,
        force=args.force,
        bag=Path(args.bag) if args.bag else None,
    )
    print(result.summary())
    print(f'closed loop: {result.json_path}; plot: {result.plot_path}')
    return 0


def _merged_hyper(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """--hyper-file, then the --hyper items on top.

    Raises:
        ConfigError: a kind's max_seconds in either disagrees with --max-seconds-per-model
            (``options.refuse_two_budgets``), or its device with --device cpu or cuda
            (``options.refuse_two_devices``).
    """
    path = getattr(args, 'hyper_file', None)
    from_file = options.hyper_file(path)
    items = options.hyper_parameters(args.hyper)
    budget = getattr(args, 'max_seconds_per_model', None)
    device = getattr(args, 'device', 'auto')
    options.refuse_two_budgets(items, budget, '--hyper {kind}.max_seconds={value}')
    options.refuse_two_devices(items, device, '--hyper {kind}.device={value}')
    options.refuse_two_budgets(
        _not_overridden(from_file, items, 'max_seconds'),
        budget,
        f'--hyper-file {path} ({{kind}}.max_seconds: {{value}})',
    )
    options.refuse_two_devices(
        _not_overridden(from_file, items, 'device'),
        device,
        f'--hyper-file {path} ({{kind}}.device: {{value}})',
    )
    merged = from_file
    for kind, values in items.items():
        merged.setdefault(kind, {}).update(values)
    return merged


def _not_overridden(
    from_file: dict[str, dict[str, Any]], items: dict[str, dict[str, Any]], key: str
) -> dict[str, dict[str, Any]]:
    """The file's hyper-parameters of the kinds whose ``key`` no --hyper item replaces."""
    overridden = {kind for kind, values in items.items() if key in values}
    return {kind: values for kind, values in from_file.items() if kind not in overridden}


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``train`` (shared by ``id-learning train`` and ``ros2 run ... train``)."""
    p.add_argument(
        '--bag', required=True, action='append', help='bag folder to train on (repeatable)'
    )
    options.robot_option(p)
    options.target_option(p)
    options.preprocessing_option(p)
    options.split_option(p)
    options.study_table_option(p)
    p.add_argument(
        '--models',
        default='all',
        help='comma-separated model kinds, e.g. rnea_id,mlp; all: every kind (default); study: '
        "the study's seven (rnea_lq,rnea_mlp,delan,lnn,lnn_mlp,mlp,lstm)",
    )
    p.add_argument('--out', required=True, help='run folder to write')
    p.add_argument(
        '--device',
        choices=('auto', 'cpu', 'cuda'),
        default='auto',
        help='auto: CUDA when available',
    )
    p.add_argument(
        '--max-seconds-per-model',
        type=options.fit_seconds,
        help='wall-clock budget per model fit [s], the identification and the diagnosis of '
        'the training part included; a fit cut short says so in the report (default: none, '
        'early stopping decides)',
    )
    p.add_argument(
        '--hyper-file',
        metavar='PATH',
        help="YAML {kind: {key: value}} of hyper-parameters (a sweep's best.yaml); --hyper "
        'items override it',
    )
    p.add_argument(
        '--hyper',
        action='append',
        metavar='KIND.KEY=VALUE',
        help='hyper-parameter override, e.g. mlp.max_epochs=50 (repeatable)',
    )
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.add_argument(
        '--force',
        action='store_true',
        help='replace a result already in --out, or an interrupted run in OUT.partial',
    )
    options.trim_option(p)


def add_train_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``train``, ``evaluate`` and ``closed-loop`` to the subcommands ``sub``."""
    p = sub.add_parser('train', help='train models on bags; write models, metrics and a report')
    add_train_arguments(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser('evaluate', help="evaluate a run's models on another recording")
    p.add_argument('--run', required=True, help='run folder written by train')
    p.add_argument(
        '--bag', required=True, action='append', help='bag folder to evaluate on (repeatable)'
    )
    p.add_argument('--out', required=True, help='folder for metrics.json, report.md and figures')
    options.robot_option(p, 'robot config YAML (default: the one the run was trained with)')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    _force_option(p)
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser(
        'closed-loop',
        help="track the run's test motion on the twin with each model as feed-forward",
    )
    p.add_argument('--run', required=True, help='run folder written by train')
    p.add_argument('--out', required=True, help='folder for closed_loop.json and the plot')
    p.add_argument(
        '--twin',
        help="twin config of the plant (default: the twin_config.yaml beside the run's bag)",
    )
    p.add_argument(
        '--bag',
        help='a twin recording the run was not trained on, tracked from its start on its own '
        "twin (default: the test part of the run's first training bag)",
    )
    p.add_argument(
        '--duration',
        type=options.finite(0.0, 86400.0, low_open=True),
        help='seconds of the test part to track; a shorter test part is tracked whole, with a '
        'warning naming both (default: the whole test part, at most 60 s)',
    )
    p.add_argument(
        '--models',
        help="comma-separated kinds (default: all of the run's; an empty list is refused)",
    )
    options.robot_option(p, 'robot config YAML (default: the one the run was trained with)')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    _force_option(p)
    p.set_defaults(func=cmd_closed_loop)


def _force_option(p: argparse.ArgumentParser) -> None:
    """--force of a command writing a result folder (never replaces its input)."""
    p.add_argument(
        '--force',
        action='store_true',
        help='replace a result already in --out (never the run read, nor a folder that is not '
        'an id_learning result)',
    )
