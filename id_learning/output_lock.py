"""The lock of an output: ``<out>.lock`` beside it, held with ``fcntl.flock`` without waiting.

A writer holds it exclusively from its checks to its last file (``output_lock``; ``locked`` for
a result folder): a second writer is refused at once, naming the first's pid. A reader that
must not lose what it reads while it reads (a replay playing a bag) holds it shared
(``read_lock``): readers share it; a writer that would replace the folder (a recorder or
``BagWriter`` with overwrite, a recovery in place) is refused, naming the reader's pid and what
it is; a reader is refused while a writer writes. Where the lock file cannot be made (a folder
nobody may write into), a reader reads without it: nobody can replace the folder there either.

The lock of a path is the lock of what it resolves to (``os.path.realpath`` of the output where it
exists, else of its parent): a link, a relative path or ``..`` meets the same lock as the target.

The file holds a writer's pid, or one line per reader: its pid, what it is and a token (``1234
replay @5``), appended when it takes the lock and blanked when it leaves. A refusal names the
readers still alive ('pid unknown' where none is). Its last holder removes it; one that locked a
file removed meanwhile locks the new one (inodes compared).
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from id_learning.output_kinds import LOCK_SUFFIX, OutputError, os_reason

__all__ = ['locked', 'named_path', 'output_lock', 'read_lock']

_LOG = logging.getLogger(__name__)

#: The output locks this process holds: lock path -> the thread holding it (``output_lock``).
_HELD: dict[Path, int] = {}
#: How often, and how far apart [s], a reader tries again while a writer holds the lock for a
#: moment (``outputs.check_bag_output`` probes it; a reader leaving takes it to remove the file).
READ_TRIES, READ_RETRY_S = 5, 0.02


def named_path(out: Path) -> Path:
    """``out``, resolved where its last part is no name (``.``, ``x/..``): siblings use it."""
    named = Path(out).resolve() if Path(out).name in ('', '.', '..') else Path(out)
    if not named.name:
        raise OutputError(f'{out}: the root folder is never an output; name a folder under it')
    return named


def _lock_path(out: Path) -> Path:
    """``<out>.lock`` beside what ``out`` resolves to (itself where it exists, else its parent)."""
    named = named_path(out)
    if os.path.lexists(named):
        real = Path(os.path.realpath(named))
    else:
        real = Path(os.path.realpath(named.parent)) / named.name
    if not real.name:
        raise OutputError(f'{out}: it is the root folder, never an output; name a folder under it')
    return real.with_name(real.name + LOCK_SUFFIX)


class _BusyError(Exception):
    """Another process holds the lock: its pid, and what it is where it reads ('' : a writer)."""

    def __init__(self, pid: str, reader: str) -> None:
        super().__init__(pid)
        self.pid, self.reader = pid, reader


#: The most of a lock file read for the names of its holders.
_HOLDERS_BYTES = 1 << 16


def _alive(pid: str) -> bool:
    """Whether a process ``pid`` runs (one of another user's counts)."""
    try:
        os.kill(int(pid), 0)
    except (ValueError, OverflowError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def _holder(fd: int) -> tuple[str, str]:
    """(pid, what reads) from a lock file; ('unknown', '') where it holds nothing yet.

    Of readers' lines (``pid what @token``) only the live ones count; several are joined.
    """
    text = os.pread(fd, _HOLDERS_BYTES, 0).decode(errors='replace')
    holders: list[tuple[str, str]] = []
    for line in text.splitlines():
        words = [word for word in line.split() if not word.startswith('@')]
        if words and (pid := words[0]) not in {h[0] for h in holders}:
            holders.append((pid, ' '.join(words[1:])))
    readers = [h for h in holders if h[1]]
    if not readers:  # a writer's pid (it holds the lock: it runs)
        return holders[0] if holders else ('unknown', '')
    holders = [h for h in readers if _alive(h[0])]
    if not holders:
        return 'unknown', ''
    others = ''.join(f'; pid {pid}, a {what}' for pid, what in holders[1:])
    return holders[0][0], holders[0][1] + others


def _take(path: Path, out: Path, mode: int) -> int:
    """An open descriptor of ``path`` that holds ``mode`` (LOCK_EX or LOCK_SH).

    Raises:
        _BusyError: another process holds it in a mode that excludes ``mode``.
        OSError: the file cannot be created or opened.
        OutputError: it kept being replaced.
    """
    for _ in range(5):  # a holder may remove the file between our open and our flock
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
        except BlockingIOError:
            pid, reader = _holder(fd)
            try:  # shared among readers alone: a writer would exclude this too
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
                is_read = mode == fcntl.LOCK_EX
            except BlockingIOError:
                is_read = False
            os.close(fd)
            raise _BusyError(pid, (reader or 'a reader') if is_read else '') from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)
    raise OutputError(f'{path}: could not be locked (it kept being replaced)')


def _refusal(out: Path, path: Path, busy: _BusyError, option: str) -> OutputError:
    if busy.reader:
        what = busy.reader if busy.reader == 'a reader' else f'a {busy.reader}'
        return OutputError(
            f'{out}: another process (pid {busy.pid}, {what}) is reading it ({path} is locked '
            f'for reading): it is not replaced under its reader; stop that process first, or '
            f'choose another {option}'
        )
    return OutputError(
        f'{out}: another process (pid {busy.pid}) is writing it ({path} is locked); wait for '
        f'it to finish, or choose another {option}'
    )


@contextlib.contextmanager
def locked(out: Path, option: str = '--out') -> Iterator[None]:
    """Hold ``<out>.lock`` exclusively (not waiting); removed on release.

    ``option``: the option or parameter that gave ``out``, as the refusal names it.

    Raises:
        OutputError: another process writes or reads ``out`` (named by its pid), or the lock
            cannot be created.
    """
    path = _lock_path(out)
    try:
        fd = _take(path, out, fcntl.LOCK_EX)
    except _BusyError as busy:
        raise _refusal(out, path, busy, option) from None
    except OSError as err:
        raise OutputError(f'{path}: {os_reason(err)} (locking {out})') from err
    try:
        try:  # a disk already full takes the file but not the pid
            os.ftruncate(fd, 0)
            os.write(fd, f'{os.getpid()}\n'.encode())
        except OSError as err:
            raise OutputError(f'{path}: {os_reason(err)} (locking {out})') from err
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


def _held_key(out: Path) -> Path:
    """The lock of ``out`` as one key however ``out`` is spelled (relative, through links)."""
    return _lock_path(out)


@contextlib.contextmanager
def output_lock(out: Path, *, option: str = '--out') -> Iterator[None]:
    """Hold ``<out>.lock`` (flock, not waiting) while writing ``out``; its parent must exist.

    ``option``: the option or parameter that gave ``out``, as the refusal names it.

    Taken again by the thread holding it, it goes on (a command holds it, the writer it calls
    takes it too); another thread or process is refused, naming the holder's pid.

    Raises:
        OutputError: another writer or a reader holds it, or it cannot be created or written.
    """
    out = Path(out)
    key, me = _held_key(out), threading.get_ident()
    if _HELD.get(key) == me:
        yield
        return
    with locked(out, option):
        _HELD[key] = me
        try:
            yield
        finally:
            del _HELD[key]


@contextlib.contextmanager
def read_lock(out: Path, *, reader: str = 'replay') -> Iterator[bool]:
    """Hold ``<out>.lock`` shared while ``out`` is read; yields whether the lock is held.

    Writers are refused meanwhile, naming this process's pid and ``reader`` (what it is). Where
    the lock file cannot be made or locked (a folder nobody may write into, a file system
    without locks), ``out`` is read without it: one debug line.

    Raises:
        OutputError: another process writes ``out`` (named by its pid).
    """
    path = _lock_path(out)
    fd = None
    for attempt in range(READ_TRIES):
        try:
            fd = _take(path, out, fcntl.LOCK_SH)
            break
        except _BusyError as busy:
            if attempt + 1 == READ_TRIES:
                raise _refusal(out, path, busy, 'bag') from None
            time.sleep(READ_RETRY_S)  # a writer's probe, or a reader leaving, holds it a moment
        except (OSError, OutputError) as err:
            _LOG.debug('%s: read without a lock (%s)', out, err)
            break
    if fd is None:
        yield False
        return
    line = f'{os.getpid()} {" ".join(reader.split()) or "reader"} @{fd}\n'.encode()
    try:
        with contextlib.suppress(OSError):  # the pid is for messages only
            _append(path, line)
        yield True
    finally:
        _release_shared(path, fd, line)


def _append(path: Path, line: bytes) -> None:
    """Add a reader's line to the lock file (appends of a line are atomic)."""
    appender = os.open(path, os.O_WRONLY | os.O_APPEND)
    try:
        os.write(appender, line)
    finally:
        os.close(appender)


def _blank(fd: int, line: bytes) -> None:
    """Blank a reader's own line in place (others' lines and appends are left as they are)."""
    text = os.pread(fd, _HOLDERS_BYTES, 0)
    at = text.find(line)
    while at > 0 and text[at - 1 : at] != b'\n':  # another line ending as this one does
        at = text.find(line, at + 1)
    if at >= 0:
        os.pwrite(fd, b' ' * (len(line) - 1), at)


def _release_shared(path: Path, fd: int, line: bytes = b'') -> None:
    """Let go of a shared lock; the last holder (none left to share it) removes the file."""
    if line:
        with contextlib.suppress(OSError):
            _blank(fd, line)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # only once no other holder is left
        if os.fstat(fd).st_ino == os.stat(path).st_ino:
            path.unlink()
    except OSError:  # another holder (BlockingIOError), or the file is gone already
        pass
    finally:
        os.close(fd)
