"""Files read whole, bounded: no device, no file over its cap, no pipe waited on without end.

Every file the package reads whole, config or not, is read through ``read_capped``: a device
(``/dev/zero`` never ends) is refused, and a file over the limit of its kind too, before it is
read into memory. The limits live beside their readers: ``MAX_CONFIG_BYTES`` (16 MiB: configs,
URDFs, parameter files), ``bag.metadata_file.MAX_BAG_METADATA_BYTES`` (4 MiB: a bag's
metadata.yaml), ``training.run_folder.MAX_RUN_DOCUMENT_BYTES`` (16 MiB: run.json),
``twin.ground_truth.MAX_GROUND_TRUTH_JSON_BYTES`` (16 MiB), ``models.artifact.MAX_METADATA_BYTES``
(64 MiB: model.json), ``evaluation.study.MAX_STUDY_TABLE_BYTES`` (1 MiB). A file of the
package's own folders (a bag's, a run's, an artifact's) must be a regular file: a FIFO there is
refused too (``regular=True``), never waited on; one the user names may be a pipe (``<(...)``),
read as it comes but never waited on without bound: a FIFO no process writes to is refused
(``PIPE_WRITER_S``), and so is one whose writer stops giving bytes (``PIPE_IDLE_S``).
"""

from __future__ import annotations

import os
import select
import stat
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from id_learning.errors import ConfigError, IdLearningError

__all__ = [
    'MAX_CONFIG_BYTES',
    'PIPE_IDLE_S',
    'PIPE_WRITER_S',
    'not_a_file',
    'pipe_waits_stop_when',
    'read_capped',
    'special_kind',
]


#: The largest config file read [bytes]. A robot, twin, mapping or parameter YAML is a few KiB
#: and a URDF a few hundred KiB (the largest of example-robot-data, TIAGo dual, 0.2 MiB): a file
#: a hundred times larger is a wrong path (a log, a bag), read whole it could fill the memory.
MAX_CONFIG_BYTES = 16 * 2**20

#: What ``stat`` calls a file that is no regular file and no folder, for messages.
_FILE_KINDS = (
    (stat.S_ISCHR, 'a character device'),
    (stat.S_ISBLK, 'a block device'),
    (stat.S_ISSOCK, 'a socket'),
    (stat.S_ISFIFO, 'a FIFO (named pipe)'),
)
#: The kinds no file is read from: a device may never end (``/dev/zero``), a socket is no file.
_DEVICE_KINDS = frozenset(name for _, name in _FILE_KINDS[:3])
#: The kinds that are no regular file and no folder (a folder fails at read, naming itself).
_SPECIAL_KINDS = frozenset(name for _, name in _FILE_KINDS)


def _mode_kind(mode: int) -> str | None:
    """What a ``st_mode`` is when it is no regular file ('a folder', 'a character device', ...)."""
    kinds = ((stat.S_ISDIR, 'a folder'), *_FILE_KINDS)
    return next((kind for is_kind, kind in kinds if is_kind(mode)), None)


def _size_text(size: int) -> str:
    """A size in bytes for messages: '16 MiB', '64 KiB', '1000 bytes'."""
    for unit, scale in (('MiB', 2**20), ('KiB', 2**10)):
        if size >= scale:
            return f'{size / scale:g} {unit}'
    return f'{size} bytes'


def not_a_file(path: Path | str) -> str | None:
    """What ``path`` is when it is no regular file ('no such file', 'a folder', 'a FIFO', ...)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return 'no such file'
    except OSError as err:
        return f'cannot be read ({err.strerror or err})'
    return _mode_kind(mode)


def special_kind(path: Path | str) -> str | None:
    """What ``path`` is when it exists but is no regular file (a folder, a FIFO, a device, ...).

    None for a regular file (or a link to one), a missing file, or one that cannot be looked
    at (reading it names why).
    """
    kind = not_a_file(path)
    return kind if kind in _SPECIAL_KINDS or kind == 'a folder' else None


#: How long a pipe may give no byte while a process holds it open for writing [s], before it is
#: refused. The writer of ``--robot <(...)`` is a program that may first have to start and work
#: (a script that writes a robot config, importing numpy: seconds on a loaded machine), so
#: the wait is generous; but it ends: a writer that is stuck, or a shell holding the FIFO open
#: and writing nothing, is named instead of being waited on for ever without a word.
PIPE_IDLE_S = 30.0
#: How long a FIFO that no process has opened for writing is waited on [s]: a FIFO gives no byte
#: and no end until a writer comes, so this is what ends a forgotten one (``mkfifo`` and no
#: writer). Short, since a writer is already there when the reader opens: bash starts a
#: ``<(...)`` writer first, and a writer that opens a FIFO waits until a reader comes. The
#: moment is for a writer started alongside the reader (a script's ``cmd > fifo &``).
PIPE_WRITER_S = 2.0
#: The longest single wait on a pipe [s]: between two, a stop asked for (``pipe_waits_stop_when``)
#: ends the read, and signal handlers run at once anyway (the wait is ``poll``).
_PIPE_SLICE_S = 0.1
#: What one read of a pipe asks for at most [bytes] (a pipe's buffer is 64 KiB on Linux).
_PIPE_CHUNK = 2**16
#: The checks that end a wait on a pipe when one is true (``pipe_waits_stop_when``).
_PIPE_STOPS: list[Callable[[], bool]] = []


@contextmanager
def pipe_waits_stop_when(stopped: Callable[[], bool]) -> Iterator[None]:
    """While the block runs, a ``read_capped`` waiting on a pipe ends as soon as ``stopped()``.

    A node notes SIGINT and SIGTERM while it starts instead of raising (``nodes.runtime``: a
    node being made is made whole, then closed); a wait for a pipe's writer would hold the
    signal for up to ``PIPE_IDLE_S``. With ``stopped`` the event its handler sets, the wait
    ends at the next slice with the library's error, which names the file.
    """
    _PIPE_STOPS.append(stopped)
    try:
        yield
    finally:
        _PIPE_STOPS.remove(stopped)


def _pipe_refusal(path: Path | str, what: str, problem: str, size: int) -> str:
    """The refusal of a pipe: the file, what it was read as, what is wrong, what it gave."""
    given = f' ({_size_text(size)} came before)' if size else ''
    return f'{path}: cannot read {what}: {problem}{given}'


def _read_pipe(
    fd: int, path: Path | str, what: str, limit: int, error: type[IdLearningError]
) -> bytes:
    """At most ``limit + 1`` bytes of a pipe opened with O_NONBLOCK, read as they come until EOF.

    Linux's ``read()`` gives 0 both at the end of what a writer wrote and while no process has
    the pipe open for writing, and ``EAGAIN`` while one has but wrote nothing yet. So a pipe
    seen held by a writer (a byte, ``EAGAIN``, or ``poll``'s hang-up once a writer came and
    went) ends at the first 0; one never seen held by a writer is waited on for
    ``PIPE_WRITER_S`` (``poll`` wakes when a writer comes and writes), one whose writer gives
    nothing for ``PIPE_IDLE_S``.

    Raises:
        IdLearningError: (``error``) the pipe ended before a byte came, no writer came, the
            writer gave nothing for ``PIPE_IDLE_S``, or a stop was asked for
            (``pipe_waits_stop_when``); each names the file and that it is a FIFO.
    """
    chunks: list[bytes] = []
    size = 0
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    opened = last_byte = time.monotonic()
    has_writer = False
    while size <= limit:
        try:
            chunk = os.read(fd, min(limit + 1 - size, _PIPE_CHUNK))
        except BlockingIOError:  # a writer holds it open and wrote nothing yet
            if not has_writer:
                has_writer, last_byte = True, time.monotonic()
        else:
            if chunk:
                chunks.append(chunk)
                size += len(chunk)
                has_writer, last_byte = True, time.monotonic()
                continue
            if has_writer:
                break  # the end of what its writer wrote
        now = time.monotonic()
        if not has_writer and now - opened > PIPE_WRITER_S:
            raise error(
                _pipe_refusal(path, what, 'a FIFO (named pipe) that no process writes to', 0)
            )
        if has_writer and now - last_byte > PIPE_IDLE_S:
            stalled = (
                f'a FIFO (named pipe) whose writer gave no byte for {PIPE_IDLE_S:g} s and kept '
                'it open: is the writer stuck?'
            )
            raise error(_pipe_refusal(path, what, stalled, size))
        if any(stopped() for stopped in _PIPE_STOPS):
            raise error(
                _pipe_refusal(path, what, 'stopped while waiting for a FIFO (named pipe)', size)
            )
        if any(events & select.POLLHUP for _, events in poller.poll(_PIPE_SLICE_S * 1000)):
            has_writer = True  # a writer came and went: the next read's 0 is its end
    if not chunks:
        raise error(
            _pipe_refusal(path, what, 'a FIFO (named pipe) that ended before giving a byte', 0)
        )
    return b''.join(chunks)


def read_capped(
    path: Path | str,
    what: str = 'config file',
    limit: int = MAX_CONFIG_BYTES,
    *,
    regular: bool = False,
    error: type[IdLearningError] = ConfigError,
) -> bytes:
    """The bytes of a file of at most ``limit`` bytes; a device or a larger file is refused.

    Every file the package reads whole comes through here, with a limit suited to what it is
    (a config, a bag's metadata.yaml, a run's run.json, ...). A device such as ``/dev/zero`` is
    refused before it is opened (it never ends, or is no file at all); a regular file larger
    than ``limit`` before a byte is read. A pipe (``--robot <(...)``, a FIFO) is read as it
    comes, up to the limit, unless ``regular``: the files inside the package's own folders
    (a bag's metadata.yaml, a run's run.json) are written as regular files, and a FIFO there
    (which nobody may ever write) is refused without waiting for a writer.

    A pipe is never waited on without bound: it is opened without blocking (a blocking open of
    a FIFO waits for a writer, and a signal whose handler does not raise does not end that
    wait), then read in short waits (``poll``). One that ends before giving a byte is refused,
    and so are one that no process opens for writing within ``PIPE_WRITER_S`` and one whose
    writer gives nothing for ``PIPE_IDLE_S``; ``pipe_waits_stop_when`` ends a wait at once.

    Args:
        path: the file.
        what: what the file is, for messages ('config file', 'URDF', 'bag metadata').
        limit: the most bytes read.
        regular: refuse anything but a regular file (a FIFO too), never blocking.
        error: the error raised: the boundary's own (``BagError`` for a bag's files).

    Raises:
        ConfigError: (or ``error``) the file is missing or unreadable, a device or socket (with
            ``regular``: a FIFO), over ``limit`` bytes, or a pipe that gave nothing (it ended
            empty, no process writes to it, its writer stalls) or was stopped while waited on;
            the message names the file and what it is.
    """
    refused = _SPECIAL_KINDS if regular else _DEVICE_KINDS
    kind = not_a_file(path)  # a FIFO is read as it comes; a missing file fails at open
    if kind in refused:
        raise error(f'{path}: cannot read {what}: {kind}, not a regular file')
    # O_NONBLOCK: a FIFO opens at once, whether a process writes to it or not (then read in short
    # waits, above); a regular file reads as without it.
    flags = os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK
    try:
        with os.fdopen(os.open(path, flags), 'rb') as stream:
            info = os.fstat(stream.fileno())
            kind = _mode_kind(info.st_mode)
            if kind in refused:  # put in place of the file after the check above
                raise error(f'{path}: cannot read {what}: {kind}, not a regular file')
            # A regular file's size is known: one past the limit is refused unread.
            is_over = stat.S_ISREG(info.st_mode) and info.st_size > limit
            if stat.S_ISFIFO(info.st_mode):
                data = _read_pipe(stream.fileno(), path, what, limit, error)
            else:
                data = b'' if is_over else stream.read(limit + 1)
    except OSError as err:
        raise error(f'{path}: cannot read {what}: {err.strerror or err}') from err
    if is_over or len(data) > limit:
        raise error(
            f'{path}: cannot read {what}: larger than {_size_text(limit)}, which no {what} is: '
            'is this the right file?'
        )
    return data
