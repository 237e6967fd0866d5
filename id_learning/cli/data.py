"""The data subcommands: ``simulate``, ``excitation``, ``import``, ``inspect``, ``bag recover``.

Each makes or examines a bag; they share nothing with training, so they live apart from it.
``add_data_commands`` adds their parsers; the handlers import their work lazily.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from id_learning.cli import options

__all__ = [
    'add_data_commands',
    'cmd_bag_recover',
    'cmd_excitation',
    'cmd_import',
    'cmd_inspect',
    'cmd_simulate',
]


def cmd_simulate(args: argparse.Namespace) -> int:
    """Run the digital twin and write a bag with its ground truth."""
    from id_learning.staged_bag import staged_bag
    from id_learning.twin import load_twin_config, simulate, write_twin_output

    # One writer per bag from the check to the ground truth beside it, written beside --out and
    # moved there whole: an interrupted simulation leaves no bag that looks complete.
    with staged_bag(Path(args.out), overwrite=args.force, inputs=[Path(args.config)]) as out:
        overrides = {}
        if args.seed is not None:
            overrides['seed'] = args.seed
        if args.robot_seed is not None:
            overrides['robot_seed'] = args.robot_seed
        if args.joint_torque_sensors:
            overrides['joint_torque_sensors'] = True
        config = load_twin_config(args.config, overrides)
        if args.duration is not None and config.excitation.file is not None:
            from id_learning.errors import ConfigError

            raise ConfigError(
                f'--duration: {args.config} plays the designed excitation '
                f"{config.excitation.file} whole; its length is the design's (design a "
                'shorter one with id-learning excitation --duration)'
            )
        if args.duration is not None:
            from dataclasses import replace

            from id_learning.twin.bounds import check_duration

            robot = config.robot
            check_duration(args.duration, robot.ipo_period_s, robot.n_joints, '--duration')
            excitation = replace(config.excitation, duration_s=args.duration)
            config = replace(config, excitation=excitation)
        result = simulate(config, progress=not args.quiet)
        write_twin_output(result, config, out, place=Path(args.out))
    print(
        f'wrote {result.recording.n_samples} samples '
        f'({result.recording.duration_s:.1f} s) to {args.out}; '
        f'effects: {", ".join(config.effects.enabled_names()) or "none"}'
    )
    return 0


def cmd_excitation(args: argparse.Namespace) -> int:
    """Design an excitation for identification; write it as a reference bag with its files."""
    import numpy as np

    from id_learning.outputs import bag_output
    from id_learning.physics.excitation_design import design_for_identification, write_design
    from id_learning.record.excitation import ExcitationConfig
    from id_learning.staged_bag import staged_bag
    from id_learning.twin.bounds import check_duration

    robot = options.load_robot(args)
    check_duration(args.duration, robot.ipo_period_s, robot.n_joints, '--duration')
    config = ExcitationConfig(duration_s=args.duration)
    if note := config.duration_note(robot.ipo_period_s):
        print(f'id-learning excitation: {note.replace("excitation.duration_s", "--duration")}',
              file=sys.stderr)  # fmt: skip
    with bag_output(Path(args.out), overwrite=args.force) as out:
        rng = np.random.default_rng(args.seed)
        design = design_for_identification(
            config, robot, rng, candidates=args.candidates, progress=not args.quiet
        )
        # Written beside --out and moved there whole (bag, excitation.json, trajectory.csv).
        with staged_bag(out, overwrite=args.force) as staged:
            write_design(design, robot, staged)
    report = design.report
    print(
        f'wrote {design.trajectory.duration_s:.1f} s ({len(design.trajectory.segments)} '
        f"segment(s) of {config.period_s:g} s) to {args.out}: the identification regressor's "
        f'condition number is {report.condition:.4g} (a random design: '
        f'{report.condition_random:.4g}, {report.columns} columns), joint-pair coverage '
        f'{report.coverage:.0%} (random: {report.coverage_random:.0%}). Play it with the '
        f'replay (-p bag:={args.out} -p "topics:=[\'/joint_states\']"), or simulate it '
        f'(excitation: {{file: {(Path(args.out) / "excitation.json").resolve()}}} in a twin '
        'config; a relative path is read beside the config); trajectory.csv holds the samples'
    )
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    """Convert CSV/NPZ logs (files or folders) into one bag of the bag contract."""
    from id_learning.dataset.importer import import_logs, load_import_mapping
    from id_learning.outputs import bag_output

    sources = [Path(source) for source in args.source]
    inputs = [*sources, Path(args.mapping), *([Path(args.robot)] if args.robot else [])]
    with bag_output(Path(args.out), overwrite=args.force, inputs=inputs) as out:  # before work
        robot = options.load_robot(args)
        reports = import_logs(
            sources,
            load_import_mapping(args.mapping),
            out,
            robot=robot,
            overwrite=args.force,
        )
    for report in reports:
        print(report.summary())
    if len(reports) > 1:
        samples = sum(report.n_rows_written for report in reports)
        segments = sum(report.n_segments for report in reports)
        print(f'{args.out}: {samples} samples in {segments} segments from {len(reports)} files')
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    """Print topics, counts, rates, jitter, gaps and ranges of a bag."""
    from id_learning.dataset.inspect import inspect_bag, plot_report, render_report

    options.refuse_contradictions(args, [('--force', '!--plot', 'there is no plot to replace')])
    plot = None
    if args.plot:  # refused before the bag is read
        from id_learning.dataset.inspect_plot import image_suffixes
        from id_learning.outputs import check_file_output

        plot = check_file_output(
            Path(args.plot), force=args.force, inputs=[Path(args.bag)], suffixes=image_suffixes()
        )
    robot = options.load_robot(args) if args.robot else None
    gravity = None
    if robot is not None:  # the label's sign and scale, judged against the URDF's gravity
        from id_learning.physics.rigid_body import RigidBodyDynamics

        gravity = RigidBodyDynamics.from_config(robot).gravity
    report = inspect_bag(Path(args.bag), robot=robot, gravity=gravity)
    print(render_report(report))
    if plot is not None:
        print(f'plot: {plot_report(report, plot)}')
    return 0


def cmd_bag_recover(args: argparse.Namespace) -> int:
    """Rebuild a torn bag (killed recorder) into a valid one."""
    from id_learning.bag.recover import recover_bag
    from id_learning.outputs import named_path

    # '.' (recovering in place, standing in the bag) has no name to build the files' names from
    bag = Path(args.bag)
    report = recover_bag(
        named_path(bag) if bag.exists() else bag, named_path(Path(args.out)) if args.out else None
    )
    print(report.summary())
    return 0


def add_data_commands(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``simulate``, ``excitation``, ``import``, ``inspect``, ``bag`` to the subcommands."""
    p = sub.add_parser('simulate', help='run the digital twin and write a bag with ground truth')
    p.add_argument(
        '--config', required=True, help='twin config YAML (e.g. config/twin_default.yaml)'
    )
    p.add_argument('--out', required=True, help='bag folder to write')
    p.add_argument(
        '--seed', type=options.seed, help="override the config's seed: excitation and sensor noise"
    )
    p.add_argument(
        '--robot-seed',
        type=options.seed,
        help="override the config's robot_seed: the robot's hidden parameters (default: seed)",
    )
    p.add_argument(
        '--duration',
        type=options.positive_float,
        help='override the excitation duration [s]; at most 86400 s (24 h), and no more than '
        'half the available memory holds (about 0.3 MB per second at an 8 ms IPO period and '
        '6 joints)',
    )
    p.add_argument(
        '--joint-torque-sensors', action='store_true', help='record joint torques in effort'
    )
    p.add_argument(
        '--force', action='store_true', help='replace a bag already at --out (only a bag)'
    )
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser(
        'excitation',
        help='design an excitation for identification: a reference bag the replay plays',
    )
    options.robot_option(p)
    p.add_argument('--out', required=True, help='bag folder to write (with excitation.json)')
    p.add_argument(
        '--duration', type=options.positive_float, default=600.0,
        help='length [s]; whole segments of 25 s and their rests (default 600)',
    )  # fmt: skip
    p.add_argument(
        '--candidates', type=options.integer(1, 1000), default=16,
        help='draws per segment the best is chosen from (default 16; 1: the random design)',
    )  # fmt: skip
    p.add_argument('--seed', type=options.seed, default=0, help='the draws (default 0)')
    p.add_argument('--force', action='store_true', help='replace a bag already at --out')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_excitation)

    p = sub.add_parser('import', help='convert CSV/NPZ logs into one bag (column-mapping YAML)')
    p.add_argument(
        'source',
        nargs='+',
        help='CSV or NPZ files, or folders of them (name order); each is a segment of the bag',
    )
    p.add_argument(
        '--mapping', required=True, help='column-mapping YAML (see config/import_example.yaml)'
    )
    p.add_argument('--out', required=True, help='bag folder to write')
    options.robot_option(
        p,
        'robot config YAML (default: MABI MAX 100): joint names and limits are checked against '
        'it; its IPO period and topics are used',
    )
    p.add_argument(
        '--force', action='store_true', help='replace a bag already at --out (only a bag)'
    )
    p.set_defaults(func=cmd_import)

    p = sub.add_parser('inspect', help='topics, counts, rate, jitter, gaps and ranges of a bag')
    p.add_argument('bag', help='bag folder')
    options.robot_option(p, 'robot config: check ranges against its limits')
    p.add_argument(
        '--plot', help='write an overview plot to this path (.png, .pdf, .svg, ...: by suffix)'
    )
    p.add_argument('--force', action='store_true', help='replace an existing --plot file')
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser('bag', help='bag maintenance')
    bag_sub = p.add_subparsers(dest='bag_command', required=True, metavar='ACTION')
    r = bag_sub.add_parser('recover', help='rebuild a torn bag (e.g. a killed recorder)')
    r.add_argument('bag', help='bag folder')
    r.add_argument(
        '--out', help='write the recovered bag here (a new or empty folder) instead of in place'
    )
    r.set_defaults(func=cmd_bag_recover)
