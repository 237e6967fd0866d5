"""``id-learning``: the offline command-line tool (simulate, import, inspect, bag, demo)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from id_learning import __version__
from id_learning.cli.paths import default_bag, default_robot_config
from id_learning.errors import IdLearningError

__all__ = ['build_parser', 'main']

_LOG = logging.getLogger('id_learning.cli')


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
    recording = load_recording(bag, robot, progress=True)
    dataset = prepare_dataset(recording, robot, PreprocessConfig(target=args.target))
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
        f'summary written to {out / "summary.md"}'
    )
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

    p = sub.add_parser('demo', help='the main job on a bag: preprocess and write a data summary')
    p.add_argument('--bag', help='bag folder (default: the shipped bags/default)')
    p.add_argument('--out', default='out/demo', help='output folder')
    p.add_argument(
        '--target',
        choices=('motor', 'joint'),
        default='motor',
        help='motor: tau_u from currents; joint: measured joint torque',
    )
    robot_option(p)
    p.set_defaults(func=cmd_demo)
    return parser


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


if __name__ == '__main__':
    sys.exit(main())
