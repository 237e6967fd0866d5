"""``id-learning``: the offline tool.

Commands: simulate, import, inspect, bag, diagnose, train, evaluate, sweep, demo; see each
command's --help.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence

from id_learning import __version__
from id_learning.cli.data import add_data_commands
from id_learning.cli.demo import add_demo_command
from id_learning.cli.diagnose import add_diagnose_command
from id_learning.cli.sweep import add_sweep_command
from id_learning.cli.train import add_train_commands
from id_learning.errors import IdLearningError

__all__ = ['build_parser', 'main', 'train_main']

_LOG = logging.getLogger('id_learning.cli')


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand (each command module adds its own)."""
    parser = argparse.ArgumentParser(prog='id-learning', description=__doc__)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('-v', '--verbose', action='store_true', help='log debug messages')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    add_data_commands(sub)  # simulate, import, inspect, bag
    add_diagnose_command(sub)
    add_train_commands(sub)  # train, evaluate
    add_sweep_command(sub)
    add_demo_command(sub)
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
