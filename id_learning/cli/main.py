"""``id-learning``: the offline tool (simulate, import, inspect, bag, train, evaluate, demo)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from id_learning import __version__
from id_learning.cli.paths import default_bag, default_robot_config
from id_learning.errors import ConfigError, DatasetError, IdLearningError

__all__ = ['build_parser', 'main', 'train_main']

_LOG = logging.getLogger('id_learning.cli')
#: ``--preprocessing`` values (``dataset.preprocess.PREPROCESS_MODES``; not imported here, so
#: that ``--help`` stays fast).
PREPROCESSING_CHOICES = ('through_filter', 'study')


def _robot(args: argparse.Namespace):
    from id_learning.robot import load_robot_config

    return load_robot_config(args.robot or default_robot_config())


def cmd_simulate(args: argparse.Namespace) -> int:
    """Run the digital twin and write a bag with its ground truth."""
    from id_learning.twin import load_twin_config, simulate, write_twin_output

    overrides = {}
    if args.seed is not None:
        overrides['seed'] = args.seed
    if args.joint_torque_sensors:
        overrides['joint_torque_sensors'] = True
    config = load_twin_config(args.config, overrides)
    if args.duration is not None:
        from dataclasses import replace

        config = replace(config, excitation=replace(config.excitation, duration_s=args.duration))
    result = simulate(config, progress=not args.quiet)
    write_twin_output(result, config, args.out, overwrite=args.force)
    print(
        f'wrote {result.recording.n_samples} samples '
        f'({result.recording.duration_s:.1f} s) to {args.out}; '
        f'effects: {", ".join(config.effects.enabled_names()) or "none"}'
    )
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    """Convert a CSV/NPZ log into a bag of the bag contract."""
    from id_learning.dataset.importer import import_log, load_import_mapping

    robot = _robot(args) if args.robot else None
    report = import_log(
        Path(args.source),
        load_import_mapping(args.mapping),
        Path(args.out),
        robot=robot,
        overwrite=args.force,
    )
    print(report.summary())
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    """Print topics, counts, rates, jitter, gaps and ranges of a bag."""
    from id_learning.dataset.inspect import inspect_bag, plot_report, render_report

    robot = _robot(args) if args.robot else None
    report = inspect_bag(Path(args.bag), robot=robot)
    print(render_report(report))
    if args.plot:
        print(f'plot: {plot_report(report, Path(args.plot))}')
    return 0


def cmd_bag_recover(args: argparse.Namespace) -> int:
    """Rebuild a torn bag (killed recorder) into a valid one."""
    from id_learning.bag.recover import recover_bag

    report = recover_bag(Path(args.bag), Path(args.out) if args.out else None)
    print(report.summary())
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job on a bag: load, preprocess, summarise with plots."""
    from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
    from id_learning.dataset.recording import load_recording
    from id_learning.evaluation.data_summary import write_summary
    from id_learning.twin import GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON

    robot = _robot(args)
    bag = Path(args.bag or default_bag())
    out = Path(args.out)
    print(f'loading {bag} ...', flush=True)
    recording = load_recording(bag, robot, require_current=args.target == 'motor', progress=True)
    preprocess = PreprocessConfig(target=args.target, mode=args.preprocessing)
    dataset = prepare_dataset(recording, robot, preprocess)
    ground_truth = tau_clean = None
    if (bag / GROUND_TRUTH_JSON).is_file():
        ground_truth = json.loads((bag / GROUND_TRUTH_JSON).read_text(encoding='utf-8'))
        import numpy as np

        with np.load(bag / GROUND_TRUTH_ARRAYS) as arrays:
            key = 'tau_u_clean' if args.target == 'motor' else 'tau_joint_clean'
            tau_clean = arrays[key].astype(float)
    summary = write_summary(dataset, robot, out, ground_truth=ground_truth, tau_clean=tau_clean)
    print(
        f'{summary.n_samples} samples, {summary.duration_s:.0f} s; '
        f'summary written to {out / "summary.md"}',
        flush=True,
    )
    if not args.skip_diagnosis:
        from id_learning.diagnosis.report import render_summary

        diagnosis_out = out / 'diagnosis'
        try:
            result = diagnose_bags(
                [bag],
                robot,
                preprocess,
                diagnosis_out,
                progress=False,
                recordings=[recording],
            )
        except DatasetError as err:  # e.g. too short: the rest of the demo still runs
            print(f'diagnosis not run: {err}', flush=True)
        else:
            print(render_summary(result))
            print(
                f'diagnosis report: {diagnosis_out / "report.md"}; waterfall plot: '
                f'{diagnosis_out / "waterfall.png"}',
                flush=True,
            )
    if args.skip_training:
        return 0
    from id_learning.training import train_run

    kinds = _kinds(args.models)
    print(
        f'training {len(kinds)} models ({", ".join(kinds)}), at most '
        f'{args.train_seconds:g} s each ...',
        flush=True,
    )
    run = train_run(
        [bag],
        robot,
        args.target,
        kinds,
        out / 'run',
        max_seconds_per_model=args.train_seconds,
        device=args.device,
        preprocess=preprocess,
    )
    print(_metrics_table(run.metrics))
    print(f'report: {run.report}', flush=True)
    if args.online_seconds > 0:
        _demo_online_check(args, bag, run, out)
    return 0


def _demo_online_check(args: argparse.Namespace, bag: Path, run: Any, out: Path) -> None:
    """Replay the test part's start through the predictor node with the run's best model."""
    from id_learning.nodes.online_check import has_ros, online_check

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


def _kinds(text: str) -> list[str]:
    """Model kinds from a comma-separated list.

    'all' is every kind the package has (registry order), 'study' the study's seven in its
    table order; both mix with other kinds: 'study,rnea_id' is the seven plus the identified
    physics.

    Raises:
        ConfigError: an unknown kind (the message lists the known ones).
    """
    from id_learning.models.registry import MODEL_KINDS, STUDY_MODELS

    groups = {'all': tuple(MODEL_KINDS), 'study': STUDY_MODELS}
    kinds: list[str] = []
    for item in (item.strip() for item in text.split(',')):
        for kind in groups.get(item, (item,) if item else ()):
            if kind not in kinds:
                kinds.append(kind)
    unknown = [kind for kind in kinds if kind not in MODEL_KINDS]
    if unknown or not kinds:
        raise ConfigError(
            f'--models: unknown model kind(s) {unknown or [text]}; known kinds: '
            f'{", ".join(MODEL_KINDS)} (or all: every kind; study: the seven of the study)'
        )
    return kinds


def _hyper(items: Sequence[str] | None) -> dict[str, dict[str, Any]]:
    """Per-kind hyper-parameters from KIND.KEY=VALUE items (VALUE read as YAML: 3, 1e-3, tanh).

    Raises:
        ConfigError: an item is not of that form.
    """
    import yaml

    hyper: dict[str, dict[str, Any]] = {}
    for item in items or ():
        name, sep, value = item.partition('=')
        kind, dot, key = name.partition('.')
        if not (sep and dot and kind and key):
            raise ConfigError(f'--hyper {item!r}: expected KIND.KEY=VALUE, e.g. mlp.max_epochs=50')
        try:
            hyper.setdefault(kind, {})[key] = yaml.safe_load(value)
        except yaml.YAMLError as err:
            raise ConfigError(f'--hyper {item!r}: cannot read the value: {err}') from err
    return hyper


def _metrics_table(metrics: dict[str, Any]) -> str:
    """Per-joint test RMSE through the label filter [N*m], with the floor, as plain text."""
    from id_learning.evaluation.study import MODEL_LABELS

    joints = metrics['joints']
    floor = metrics.get('label_noise_floor_nm')
    width = 24

    def row(label: str, values: Sequence[float], last: str = '') -> str:
        return f'{label:<{width}}' + ''.join(f'{x:>10.3g}' for x in values) + last

    head = f'{"test RMSE through filter":<{width}}' + ''.join(f'{j:>10}' for j in joints)
    lines = [head + f'{"mean norm.":>12}']
    for kind, entry in metrics['models'].items():
        label = MODEL_LABELS.get(kind, kind)
        lines.append(row(label, entry['rmse_nm'], f'{entry["mean_rmse_normalised"]:>12.3g}'))
    if floor is not None:
        lines.append(row('label-noise floor', floor))
        lines += ['', f'{"x label-noise floor":<{width}}' + ''.join(f'{j:>10}' for j in joints)]
        for kind, entry in metrics['models'].items():
            ratio = entry.get('rmse_through_filter_over_floor')
            if ratio is not None:
                lines.append(row(MODEL_LABELS.get(kind, kind), ratio))
    lines += [
        '',
        f'{"study way [N*m]":<{width}}'
        + ''.join(f'{j:>10}' for j in joints)
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


def diagnose_bags(
    bags: Sequence[Path],
    robot: Any,
    preprocess: Any,
    out: Path,
    *,
    effects: Sequence[str] | None = None,
    progress: bool = True,
    recordings: Sequence[Any] | None = None,
) -> Any:
    """Diagnose bags; write report.md, effects.json, figures and the rnea_effects model to ``out``.

    ``preprocess``: the ``PreprocessConfig`` (target and mode). ``recordings``: the bags already
    loaded (same order), to skip reading them again.

    Returns:
        the ``DiagnosisResult``.
    """
    from id_learning.dataset.recording import load_recording
    from id_learning.diagnosis import DiagnosisConfig, diagnose
    from id_learning.models.effects import RneaEffectsModel
    from id_learning.models.registry import save_model

    target = preprocess.target
    settings: dict[str, Any] = {'preprocess': preprocess}
    if effects:
        settings['effects'] = tuple(effects)
    config = DiagnosisConfig(**settings)
    if recordings is None:
        recordings = []
        for bag in bags:
            print(f'loading {bag} ...', flush=True)
            recordings.append(
                load_recording(
                    Path(bag), robot, require_current=target == 'motor', progress=progress
                )
            )
    print('diagnosing: nominal model vs measurements, forward selection of named effects ...',
          flush=True)  # fmt: skip
    result = diagnose(recordings, robot, config, out_dir=out)
    model = RneaEffectsModel.from_augmented(
        result.augmented_model, source=str(out / 'effects.json')
    )
    save_model(model, out / 'model', extra={'diagnosis': {'sources': result.sources}})
    return result


def cmd_diagnose(args: argparse.Namespace) -> int:
    """Find the effects the nominal model misses; report, effects.json and a model artifact."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.diagnosis.report import render_summary

    out = Path(args.out)
    result = diagnose_bags(
        [Path(b) for b in args.bag],
        _robot(args),
        PreprocessConfig(target=args.target, mode=args.preprocessing),
        out,
        effects=_names(args.effects) if args.effects else None,
        progress=not args.quiet,
    )
    print(render_summary(result))
    print(
        f'report: {out / "report.md"}; effects: {out / "effects.json"}; waterfall: '
        f'{out / "waterfall.png"}; model (rnea_effects): {out / "model"}'
    )
    return 0


def _names(text: str) -> list[str]:
    return [item.strip() for item in text.split(',') if item.strip()]


def cmd_train(args: argparse.Namespace) -> int:
    """Train models on bags; write models, metrics.json and report.md into the run folder."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.training import train_run

    robot = _robot(args)
    run = train_run(
        [Path(b) for b in args.bag],
        robot,
        args.target,
        _kinds(args.models),
        Path(args.out),
        hyper=_hyper(args.hyper),
        max_seconds_per_model=args.max_seconds_per_model,
        progress=not args.quiet,
        device=args.device,
        preprocess=PreprocessConfig(mode=args.preprocessing),
    )
    print(_metrics_table(run.metrics))
    print(f'models: {run.out / "models"}; metrics: {run.metrics_path}; report: {run.report}')
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Evaluate every model of a run on other recordings."""
    from id_learning.training import evaluate_run, read_run

    run_dir = Path(args.run)
    if args.robot:
        robot = _robot(args)
    else:
        from id_learning.robot import load_robot_config

        source = read_run(run_dir).get('robot_config')
        robot = load_robot_config(source) if source else _robot(args)
    result = evaluate_run(
        run_dir, [Path(b) for b in args.bag], robot, Path(args.out), progress=not args.quiet
    )
    print(_metrics_table(result.metrics))
    print(f'metrics: {result.out / "metrics.json"}; report: {result.report}')
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(prog='id-learning', description=__doc__)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('-v', '--verbose', action='store_true', help='log debug messages')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    def robot_option(
        p: argparse.ArgumentParser, help_text: str = 'robot config YAML (default: MABI MAX 100)'
    ) -> None:
        p.add_argument('--robot', help=help_text)

    p = sub.add_parser('simulate', help='run the digital twin and write a bag with ground truth')
    p.add_argument(
        '--config', required=True, help='twin config YAML (e.g. config/twin_default.yaml)'
    )
    p.add_argument('--out', required=True, help='bag folder to write')
    p.add_argument('--seed', type=int, help='override the config seed')
    p.add_argument('--duration', type=float, help='override the excitation duration [s]')
    p.add_argument(
        '--joint-torque-sensors', action='store_true', help='record joint torques in effort'
    )
    p.add_argument('--force', action='store_true', help='overwrite an existing bag folder')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser('import', help='convert a CSV/NPZ log into a bag (column-mapping YAML)')
    p.add_argument('source', help='CSV or NPZ file')
    p.add_argument(
        '--mapping', required=True, help='column-mapping YAML (see config/import_example.yaml)'
    )
    p.add_argument('--out', required=True, help='bag folder to write')
    robot_option(p, 'robot config: check joint names against it and use its IPO period and topics')
    p.add_argument('--force', action='store_true', help='overwrite an existing bag folder')
    p.set_defaults(func=cmd_import)

    p = sub.add_parser('inspect', help='topics, counts, rate, jitter, gaps and ranges of a bag')
    p.add_argument('bag', help='bag folder')
    robot_option(p, 'robot config: check ranges against its limits')
    p.add_argument('--plot', help='write a PNG overview to this path')
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser('bag', help='bag maintenance')
    bag_sub = p.add_subparsers(dest='bag_command', required=True, metavar='ACTION')
    r = bag_sub.add_parser('recover', help='rebuild a torn bag (e.g. a killed recorder)')
    r.add_argument('bag', help='bag folder')
    r.add_argument('--out', help='write the recovered bag here instead of in place')
    r.set_defaults(func=cmd_bag_recover)

    p = sub.add_parser(
        'diagnose',
        help='name the physical effects the nominal model misses, add them, show the gap shrink',
    )
    p.add_argument('--bag', required=True, action='append', help='bag folder (repeatable)')
    p.add_argument(
        '--out', required=True, help='folder for report.md, effects.json, figures and model/'
    )
    target_option(p)
    preprocessing_option(p)
    p.add_argument(
        '--effects',
        help='comma-separated candidate effects to try (default: the whole library)',
    )
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    robot_option(p)
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser('train', help='train models on bags; write models, metrics and a report')
    add_train_arguments(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser('evaluate', help="evaluate a run's models on another recording")
    p.add_argument('--run', required=True, help='run folder written by train')
    p.add_argument(
        '--bag', required=True, action='append', help='bag folder to evaluate on (repeatable)'
    )
    p.add_argument('--out', required=True, help='folder for metrics.json, report.md and figures')
    robot_option(p, 'robot config YAML (default: the one the run was trained with)')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser(
        'demo',
        help='the main job on a bag: data summary, then train all seven models with a report',
    )
    p.add_argument('--bag', help='bag folder (default: the shipped bags/default)')
    p.add_argument('--out', default='out/demo', help='output folder (the run goes to OUT/run)')
    target_option(p)
    preprocessing_option(p)
    p.add_argument(
        '--models',
        default=DEMO_MODELS,
        help=f'comma-separated model kinds to train (default: {DEMO_MODELS})',
    )
    p.add_argument(
        '--train-seconds',
        type=_positive_float,
        default=DEMO_SECONDS_PER_MODEL,
        help=f'wall-clock budget per model fit [s] (default {DEMO_SECONDS_PER_MODEL:g})',
    )
    p.add_argument('--skip-training', action='store_true', help='only write the data summary')
    p.add_argument('--skip-diagnosis', action='store_true', help='do not run the diagnosis')
    p.add_argument(
        '--online-seconds',
        type=float,
        default=30.0,
        help='seconds of the test part replayed through the predictor node (0: skip)',
    )
    p.add_argument('--device', choices=('auto', 'cpu', 'cuda'), default='auto')
    robot_option(p)
    p.set_defaults(func=cmd_demo)
    return parser


#: The demo trains the study's seven, the identified physics and the diagnosed model.
DEMO_MODELS = 'study,rnea_id,rnea_effects'
#: Budget per model in ``demo``: seven models on the shipped bag within 10 minutes on 2 cores.
DEMO_SECONDS_PER_MODEL = 60.0


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text}')
    return value


def target_option(p: argparse.ArgumentParser) -> None:
    """The --target option: which torque is the label."""
    p.add_argument(
        '--target',
        choices=('motor', 'joint'),
        default='motor',
        help='motor: tau_u from currents (default); joint: measured joint torque',
    )


def preprocessing_option(p: argparse.ArgumentParser) -> None:
    """The --preprocessing option: fit through the label filter, or the study's way."""
    p.add_argument(
        '--preprocessing',
        choices=PREPROCESSING_CHOICES,
        default='through_filter',
        help="through_filter (default): models see a controller's inputs and their torque is "
        "filtered like the labels before it meets them; study: the reference study's pipeline "
        '(low-passed inputs, torque compared with the low-passed labels as is), for comparison',
    )


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``train`` (shared by ``id-learning train`` and ``ros2 run ... train``)."""
    p.add_argument(
        '--bag', required=True, action='append', help='bag folder to train on (repeatable)'
    )
    p.add_argument('--robot', help='robot config YAML (default: MABI MAX 100)')
    target_option(p)
    preprocessing_option(p)
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
        type=_positive_float,
        help='wall-clock budget per model fit [s] (default: none, early stopping decides)',
    )
    p.add_argument(
        '--hyper',
        action='append',
        metavar='KIND.KEY=VALUE',
        help='hyper-parameter override, e.g. mlp.max_epochs=50 (repeatable)',
    )
    p.add_argument('--quiet', action='store_true', help='no progress bars')


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; package errors print one clear line and exit with status 2."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format='%(levelname)s %(name)s: %(message)s',
    )
    try:
        return int(args.func(args))
    except IdLearningError as err:
        print(f'id-learning {args.command}: error: {err}', file=sys.stderr)
        return 2


def _without_ros_arguments(argv: Sequence[str]) -> list[str]:
    """Drop the ``--ros-args ... [--]`` block that ``ros2 run`` may append."""
    out: list[str] = []
    inside = False
    for item in argv:
        if item == '--ros-args':
            inside = True
        elif inside and item == '--':
            inside = False
        elif not inside:
            out.append(item)
    return out


def train_main(argv: Sequence[str] | None = None) -> int:
    """``ros2 run id_learning train ...``: the ``train`` subcommand as its own program."""
    args = sys.argv[1:] if argv is None else list(argv)
    return main(['train', *_without_ros_arguments(args)])


if __name__ == '__main__':
    sys.exit(main())
