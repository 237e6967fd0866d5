"""A bag written whole or not at all: written beside its place, renamed into it once complete.

``BagWriter`` closes a bag with its ``metadata.yaml`` whatever stopped the writing (a Ctrl-C
too), so a bag written in place and interrupted looks complete: every reader takes its first
minutes for the whole recording. ``staged_bag`` has the bag written into a hidden sibling
folder, ``.<name>.writing/<name>`` (the same file system, so the final rename is atomic, and the
bag keeps the name ``BagWriter`` builds its ``.mcap`` file names from), and renames it to
``<out>`` only when the writer finished without an error. A writer stopped by a signal or an
error leaves ``<out>`` as it was (absent, or the bag ``--force`` was to replace); a writer killed
outright (SIGKILL, power loss) leaves only the hidden folder, which the next writer of the same
``<out>`` removes, saying so.

It holds ``<out>.lock`` (``outputs.bag_output``) throughout, so the hidden folder of a writer
still running is never taken for a leftover.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import signal
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

from id_learning.bag.writer import BagWriteError
from id_learning.errors import IdLearningError
from id_learning.outputs import LOCK_SUFFIX, OutputError, bag_output, os_reason, replace_folder

__all__ = ['STAGING_SUFFIX', 'staged_bag', 'staging_folder']

_LOG = logging.getLogger(__name__)

#: The hidden sibling ``.<name><STAGING_SUFFIX>`` a bag is written in until it is complete.
STAGING_SUFFIX = '.writing'


def staging_folder(out: Path) -> Path:
    """``.<name>.writing`` beside ``out``: where its bag is written until it is complete."""
    return out.with_name(f'.{out.name}{STAGING_SUFFIX}')


@contextlib.contextmanager
def staged_bag(
    out: Path,
    *,
    overwrite: bool = False,
    inputs: Sequence[Path] = (),
    flag: str = '--force',
    option: str = '--out',
) -> Iterator[Path]:
    """Yield the folder to write the bag of ``out`` in; it becomes ``out`` once complete.

    Args:
        out: the bag folder (``--out``); checked as ``outputs.bag_output`` checks it.
        overwrite: replace a bag already at ``out`` (only a bag; only once the new one is whole).
        inputs: what the command reads; ``out`` may not be, hold or lie in one.
        flag: how messages name ``overwrite``.
        option: the option that gave ``out``, as messages name it.

    Raises:
        OutputError: ``out`` is refused, another process writes it, a leftover staging folder
            holds what no writer of ``out`` put there, or the folder could not be moved into
            place (the OS's reason); ``out`` is then as it was.
        IdLearningError: what the writer raised, with where the bag is (not) left.
    """
    # The lock: no other writer of ``out`` runs while its staging folder is looked at.
    with bag_output(out, overwrite=overwrite, inputs=inputs, flag=flag, option=option) as target:
        root = staging_folder(target)
        _remove_leftover(root, target)
        try:
            root.mkdir()
        except OSError as err:
            raise OutputError(f'{root}: {os_reason(err)} (writing {target})') from err
        staged = root / target.name
        try:
            try:
                yield staged
            except BagWriteError as err:  # the staged bag is removed below: nothing is kept
                raise OutputError(
                    f'{target}: writing failed: {err.reason}; {_as_it_was(target)} (free space '
                    'and run it again)'
                ) from err
            except IdLearningError as err:  # the hidden folder, removed below, is not named
                said = str(err).replace(str(staged), str(target))
                raise type(err)(f'{said}; {_as_it_was(target)}') from err
            except OSError as err:
                raise OutputError(f'{target}: {os_reason(err)} (writing it); '
                                  f'{_as_it_was(target)}') from err  # fmt: skip
            left = _as_it_was(target)
            if not (staged / 'metadata.yaml').is_file():  # the caller wrote no bag
                raise OutputError(f'{target}: no complete bag was written; {left}')
            with _signals_deferred():  # both renames of a replacement, or neither
                try:
                    replace_folder(staged, target)
                except OSError as err:
                    raise OutputError(
                        f'{target}: {os_reason(err)} (moving the written bag there from '
                        f'{staged}); {left}'
                    ) from err
        finally:
            shutil.rmtree(root, ignore_errors=True)


def _as_it_was(out: Path) -> str:
    """Where a stopped writer leaves ``out``, for messages."""
    return f'{out} is as it was' if out.exists() else f'nothing was written to {out}'


def _remove_leftover(root: Path, out: Path) -> None:
    """Remove the staging folder a killed writer of ``out`` left; refuse one that is not ours.

    Ours holds at most the bag folder named as ``out`` and that bag's lock.

    Raises:
        OutputError: ``root`` is no folder, or holds something else.
    """
    if not (root.exists() or root.is_symlink()):
        return
    try:
        entries = None if root.is_symlink() or not root.is_dir() else sorted(root.iterdir())
    except OSError as err:
        raise OutputError(f'{root}: {os_reason(err)} (writing {out})') from err
    ours = {out.name, out.name + LOCK_SUFFIX}
    if entries is None or any(entry.name not in ours for entry in entries):
        raise OutputError(
            f'{root}: is where {out} is written until it is complete, but it holds what no '
            f'writer of {out} put there; move it away'
        )
    shutil.rmtree(root)
    _LOG.warning('removed %s: a bag left unfinished by a writer of %s that was killed', root, out)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP wait (blocked, not lost) until the block has run.

    A replacement is two renames (the old bag aside, the new one in); a signal between them
    would leave neither at ``out``. Only the main thread receives them (Python's handlers).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
