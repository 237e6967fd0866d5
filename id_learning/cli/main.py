"""``id-learning``: the offline tool.

Commands: simulate, excitation, import, inspect, bag, diagnose, train, evaluate, closed-loop,
sweep, demo; see each command's --help.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import FrameType

from id_learning import __version__
from id_learning.cli.data import add_data_commands
from id_learning.cli.demo import add_demo_command
from id_learning.cli.diagnose import add_diagnose_command
from id_learning.cli.options import empty_paths
from id_learning.cli.streams import Guarded, failure
from id_learning.cli.sweep import add_sweep_command
from id_learning.cli.train import add_train_commands
from id_learning.errors import IdLearningError

__all__ = ['HungUp', 'Terminated', 'build_parser', 'main', 'stdout_closed', 'train_main']

_LOG = logging.getLogger('id_learning.cli')

#: The commands that write a result folder through ``outputs.result_folder``.
_RESULT_COMMANDS = frozenset({'train', 'evaluate', 'closed-loop', 'diagnose', 'demo'})


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises KeyboardInterrupt: every writer cleans up alike."""

    number = signal.SIGTERM
    word = 'terminated'


class HungUp(Terminated):
    """SIGHUP (its terminal or ssh session closed): stops the command as SIGTERM does."""

    number = signal.SIGHUP
    word = 'hung up (SIGHUP)'


class _Stopping(logging.Filter):
    """Drops Optuna's report of the trial a signal stopped (a traceback): one line says it."""

    def __init__(self) -> None:
        super().__init__()
        self.stopped = False

    def filter(self, record: logging.LogRecord) -> bool:
        return not self.stopped


@contextlib.contextmanager
def _signals_raise() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt, SIGTERM ``Terminated``, SIGHUP ``HungUp``, while it runs.

    SIGHUP's default would end the process at once, leaving a half-written bag or lock behind
    (a closed terminal or ssh session): it stops the command as SIGTERM does.

    Only the first: a signal repeated while its cleanup runs (Ctrl-C pressed again) is ignored,
    so that the cleanup finishes, and the tool still ends with its one line and status. A
    signal ignored when the tool started (a background job) stays ignored; the handlers before
    are restored after (``main`` may run in a process that goes on), except after a signal
    stopped the command: the process is ending, and a further signal must not turn its exit
    into a traceback or a death by signal.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stopping = _Stopping()
    raised = {signal.SIGINT: KeyboardInterrupt, signal.SIGTERM: Terminated, signal.SIGHUP: HungUp}
    defaults = {
        signal.SIGINT: signal.default_int_handler,
        signal.SIGTERM: signal.SIG_DFL,
        signal.SIGHUP: signal.SIG_DFL,
    }

    def handle(number: int, frame: FrameType | None) -> None:
        if stopping.stopped:
            return  # the first one's cleanup is running: let it finish
        stopping.stopped = True
        raise raised[signal.Signals(number)]

    previous = {number: signal.getsignal(number) for number in raised}
    for number, handler in previous.items():
        if handler is defaults[number]:
            signal.signal(number, handle)
    optuna = logging.getLogger('optuna.study._optimize')
    optuna.addFilter(stopping)
    try:
        yield
    finally:
        optuna.removeFilter(stopping)
        for number, handler in previous.items():
            if handler is defaults[number]:
                # Ignored, not handled, once stopped: Python puts its own handlers back to the
                # default (death by signal) while the interpreter shuts down, not SIG_IGN.
                signal.signal(number, signal.SIG_IGN if stopping.stopped else handler)


def _stat(path: Path | None) -> tuple[int, int] | None:
    """(inode, modification time [ns]) of ``path``, or None: did a command write there."""
    try:
        status = os.stat(path) if path is not None else None
    except OSError:
        return None
    return None if status is None else (status.st_ino, status.st_mtime_ns)


def _written(args: argparse.Namespace) -> Path | None:
    """The bag, recovered bag or plot a command writes (None: no such output, or a result)."""
    if args.command in ('simulate', 'import', 'excitation'):
        return Path(args.out)
    if args.command == 'bag':  # in place, metadata.yaml is replaced last, and only then
        return Path(args.out) if args.out else Path(args.bag) / 'metadata.yaml'
    plot = getattr(args, 'plot', None) if args.command == 'inspect' else None
    return Path(plot) if plot else None


def _left(args: argparse.Namespace, before: tuple[int, int] | None) -> str:
    """What a command stopped by a signal leaves, and where: the rest of its one line."""
    if args.command in _RESULT_COMMANDS:
        from id_learning.output_kinds import read_marker
        from id_learning.outputs import partial_path

        out = Path(args.out)
        for partial in dict.fromkeys((partial_path(out), partial_path(out.resolve()))):
            if partial.is_dir() and read_marker(partial) is not None:
                return (
                    f'what was written so far is in {partial}, an incomplete result that '
                    '--force replaces'
                )
        return f'nothing was written to {out}'
    if args.command == 'sweep':
        return 'the study keeps the trials that finished; run the same sweep again to go on'
    path = _written(args)
    if path is None:
        return 'nothing was written'
    changed = _stat(path) != before
    if args.command == 'bag' and args.out:
        return f'{path} holds the recovered bag' if changed else f'nothing was written to {path}'
    if args.command == 'bag':
        return (
            f'{path.parent} holds the recovered bag' if changed else f'{path.parent} is as it was'
        )
    if args.command == 'inspect':
        return f'{path} was written' if changed else 'nothing was written'
    return (
        f'{path} holds an incomplete bag; delete it, or pass --force to replace it'
        if changed
        else f'nothing was written to {path}'
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand (each command module adds its own)."""
    parser = argparse.ArgumentParser(prog='id-learning', description=__doc__)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('-v', '--verbose', action='store_true', help='log debug messages')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    add_data_commands(sub)  # simulate, excitation, import, inspect, bag
    add_diagnose_command(sub)
    add_train_commands(sub)  # train, evaluate
    add_sweep_command(sub)
    add_demo_command(sub)
    return parser


def stdout_closed() -> int:
    """After a write to a closed standard output (``| head``): exit quietly, with 141.

    The Python documentation's way (signal, 'Note on SIGPIPE'): what is left to write goes to
    /dev/null, so that the flush at exit raises nothing more. 141 is 128 + SIGPIPE, the status a
    shell gives a program a closed pipe ended.
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no file descriptor behind sys.stdout (a test's capture)
        pass
    finally:
        os.close(devnull)
    return 128 + signal.SIGPIPE


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; package errors print one clear line and exit with status 2.

    Ctrl-C (SIGINT), SIGTERM and SIGHUP print one line saying what is left where and exit with
    130, 143 and 129 (128 + the signal's number): the writers clean up as for any failure. A closed
    standard output (``id-learning inspect BAG | head -1``, also under ``--help``) ends the
    command quietly with 141 (``stdout_closed``); the writers clean up alike. A standard output
    or error that cannot be written otherwise (closed when the tool started, a full disk) does
    not stop the command: what it wrote is kept, one line says what could not be shown, on the
    stream that still works, and the status is 1 where the command succeeded
    (``cli.streams``).
    """
    real = sys.stdout, sys.stderr
    out, err = Guarded(real[0]), Guarded(real[1])
    sys.stdout, sys.stderr = out, err
    stopped: SystemExit | None = None
    try:
        try:
            try:
                code = _run(argv)
            except SystemExit as stop:  # --help, --version, a usage error
                stopped = stop
                code = stop.code if isinstance(stop.code, int) else 0 if stop.code is None else 2
            finally:  # a closed pipe raises here, not at the interpreter's exit (after --help too)
                out.flush()
                err.flush()
        except BrokenPipeError:
            return stdout_closed()
        result = _unwritten(code, out, err)
    finally:
        sys.stdout, sys.stderr = real
    if stopped is not None and result == code:
        raise stopped  # argparse's own exit, as callers of main() expect it
    return result


def _unwritten(code: int, out: Guarded, err: Guarded) -> int:
    """``code``, or 1 after one line on what could not be written (on the stream that works)."""
    problems = [p for p in (failure('output', out), failure('error', err)) if p is not None]
    if not problems:
        return code
    line = f'id-learning: error: {"; ".join(problems)}\n'
    for stream in (err, out):
        if stream.error is None and stream.stream is not None:
            stream.write(line)
            stream.flush()
            break
    return code or 1


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    empty = empty_paths(args, sys.argv[1:] if argv is None else argv)
    if empty:  # Path('') is the working folder: never a bag, a run or an output meant
        parser.error(f'{", ".join(empty)}: an empty path; name the file or folder')
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format='%(levelname)s %(name)s: %(message)s',
    )
    before = _stat(_written(args))
    try:
        with _signals_raise():
            return int(args.func(args))
    except IdLearningError as err:
        print(f'id-learning {args.command}: error: {err}', file=sys.stderr)
        return 2
    except OSError as err:
        if err.errno != errno.ENAMETOOLONG:
            raise
        # Outputs are refused so before any work (outputs.check_target); this is the net for a
        # path a command looks at before that, or an input's.
        where = f'{err.filename}: ' if err.filename is not None else ''
        print(
            f'id-learning {args.command}: error: {where}{err.strerror}; choose a shorter path',
            file=sys.stderr,
        )
        return 2
    except (MemoryError, ImportError) as err:
        # Under an address-space limit (ulimit -v) torch cannot map its libraries and numpy
        # cannot allocate: the environment's limit, said in one line, not a traceback.
        what = 'out of memory' if isinstance(err, MemoryError) else 'cannot load a module'
        print(
            f'id-learning {args.command}: error: {what} ({err or type(err).__name__})'
            f'{_memory_limit()}; {_left(args, before)}',
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt as err:
        number, stopped = (
            (err.number, err.word)
            if isinstance(err, Terminated)
            else (signal.SIGINT, 'interrupted')
        )
        print(f'id-learning {args.command}: {stopped}; {_left(args, before)}', file=sys.stderr)
        return 128 + number


def _memory_limit() -> str:
    """'; the process may use N MiB of address space (ulimit -v)' where limited, else ''."""
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return ''
    return f'; the process may use {soft / 2**20:.0f} MiB of address space (ulimit -v): raise it'


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
