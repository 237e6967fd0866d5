"""The console scripts: each program is imported only once Ctrl-C and SIGTERM are handled.

A program's module is heavy (a node imports rclpy, torch and the core: seconds on a loaded
machine). It is imported here, inside the handling, so that a signal while Python imports it ends
the program with one line, ``<program>: interrupted while starting; nothing was done`` (or
``terminated``), and the shell's status, 130 or 143 (128 + the signal's number), never a
traceback. From then on the program's own handling applies: ``cli.main`` says in one line what
is left where; ``nodes.runtime.run_node`` lets a node that is up finish its work and report. Only
the interpreter's own start, before this module runs (under 0.1 s), is Python's.

``python -m id_learning.entry PROGRAM [ARGS...]`` runs a program by name, as its console script
does (the nodes the tests and the online check start).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = [
    'PROGRAMS',
    'cli',
    'predictor',
    'recorder',
    'replay',
    'run',
    'stopped_while_starting',
    'train',
]

#: Each program's module and function (``main(args=None) -> int``).
PROGRAMS = {
    'id-learning': ('id_learning.cli.main', 'main'),
    'train': ('id_learning.cli.main', 'train_main'),
    'recorder': ('id_learning.nodes.recorder', 'main'),
    'replay': ('id_learning.nodes.replay', 'main'),
    'predictor': ('id_learning.nodes.predictor', 'main'),
}


class _Terminated(KeyboardInterrupt):
    """SIGTERM while a program starts, raised where Ctrl-C raises KeyboardInterrupt."""

    number = signal.SIGTERM
    word = 'terminated'


class _HungUp(_Terminated):
    """SIGHUP (its terminal or ssh session closed) while a program starts."""

    number = signal.SIGHUP
    word = 'hung up (SIGHUP)'


def stopped_while_starting(program: str, err: KeyboardInterrupt) -> int:
    """Say in one line that ``program`` stopped before it did anything; the exit status."""
    number, stopped = (
        (err.number, err.word) if isinstance(err, _Terminated) else (signal.SIGINT, 'interrupted')
    )
    print(f'{program}: {stopped} while starting; nothing was done', file=sys.stderr, flush=True)
    return 128 + number


def _raise(number: int, frame: FrameType | None) -> None:
    raised: dict[int, type[KeyboardInterrupt]] = {
        signal.SIGTERM: _Terminated,
        signal.SIGHUP: _HungUp,
    }
    raise raised.get(number, KeyboardInterrupt)


@contextmanager
def _signals_raise() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise while the block runs (ignored ones stay ignored).

    After the block SIGINT raises KeyboardInterrupt again (Python's default) and SIGTERM and
    SIGHUP end the process (the program's own handling takes over from there).
    """
    defaults = {
        signal.SIGINT: signal.default_int_handler,
        signal.SIGTERM: signal.SIG_DFL,
        signal.SIGHUP: signal.SIG_DFL,
    }
    previous = {number: signal.getsignal(number) for number in defaults}
    for number, handler in previous.items():
        if handler is defaults[number]:
            signal.signal(number, _raise)
    try:
        yield
    finally:
        for number, handler in previous.items():
            if handler is defaults[number]:
                signal.signal(number, handler)


def run(program: str) -> int:
    """Import ``program`` inside the signal handling, then run it; its exit status.

    A working folder deleted under the shell is refused first, in one line: torch's MKL cannot
    load its libraries from there and ends the process with a line that does not say why.
    """
    module, function = PROGRAMS[program]
    try:
        os.getcwd()
    except FileNotFoundError:
        print(
            f'{program}: error: the working folder no longer exists (deleted after the shell '
            'entered it); cd into an existing folder',
            file=sys.stderr,
        )
        return 2
    try:
        with _signals_raise():
            main: Callable[[], int] = getattr(importlib.import_module(module), function)
        return int(main())
    except KeyboardInterrupt as err:  # importing, or before the program's own handling began
        return stopped_while_starting(program, err)


def cli() -> int:
    """``id-learning``."""
    return run('id-learning')


def train() -> int:
    """``train``: the ``train`` command as a program of its own."""
    return run('train')


def recorder() -> int:
    """``recorder``: the recorder node."""
    return run('recorder')


def replay() -> int:
    """``replay``: the replay node."""
    return run('replay')


def predictor() -> int:
    """``predictor``: the predictor node."""
    return run('predictor')


if __name__ == '__main__':
    if len(sys.argv) < 2 or sys.argv[1] not in PROGRAMS:
        print(f'usage: python -m id_learning.entry {{{",".join(PROGRAMS)}}} [ARGS...]',
              file=sys.stderr)  # fmt: skip
        raise SystemExit(2)
    name = sys.argv.pop(1)
    sys.argv[0] = name
    raise SystemExit(run(name))
