"""Result folders written whole or not at all: a partial sibling, a lock, one rename at the end.

Every command that writes a result folder (``train``, ``evaluate``, ``closed-loop``,
``diagnose``, ``demo``) writes it through ``result_folder``:

- ``<out>.lock`` (a sibling) is locked with ``fcntl.flock``, without waiting: a second writer to
  the same ``<out>`` is refused at once, naming the holder's pid;
- everything is written into ``<out>.partial``, which holds ``incomplete.json`` (the command, pid,
  host and start time) until it is complete, so that a folder left by a killed command says what
  it is;
- when complete, the marker is removed and ``<out>.partial`` renamed to ``<out>``. An existing
  result there is replaced only with ``force``, and then atomically: moved aside, the new one
  renamed in, the old one removed. A folder that is the input of the command, or that holds
  anything other than an id_learning result, is never replaced.

A failure while writing (disk full, a file size limit, no permission) raises ``OutputError``
naming the path and the operating system's reason; nothing is left under ``<out>``, and the
partial folder is removed unless the writer asked to keep it (a training run keeps the models it
has fitted). Consumers ask ``incomplete_reason`` whether a folder they read is complete.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import logging
import os
import platform
import shutil
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from id_learning.errors import ConfigError

__all__ = [
    'INCOMPLETE_FILE',
    'LOCK_SUFFIX',
    'PARTIAL_SUFFIX',
    'RESULT_FILES',
    'OutputError',
    'ResultFolder',
    'check_output',
    'incomplete_reason',
    'os_reason',
    'partial_path',
    'replace_folder',
    'result_folder',
    'write_text_atomic',
]

_LOG = logging.getLogger(__name__)

PARTIAL_SUFFIX = '.partial'
LOCK_SUFFIX = '.lock'
#: Where a replaced result waits, for a moment, to be removed.
REPLACED_SUFFIX = '.replaced'
INCOMPLETE_FILE = 'incomplete.json'
INCOMPLETE_FORMAT = 'id_learning.incomplete/1'
#: The documents that mark a folder as an id_learning result, with what they say it is: only
#: such a folder is ever replaced.
RESULT_FILES = {
    'run.json': 'a training run',
    'metrics.json': 'an evaluation',
    'closed_loop.json': 'a closed-loop result',
    'effects.json': 'a diagnosis',
    'summary.md': 'a demo',
    INCOMPLETE_FILE: 'an incomplete result',
}


class OutputError(ConfigError):
    """An output cannot be written: names the path and the reason (the OS's, or a conflict).

    A ``ConfigError``: the ``--out`` given cannot be honoured (callers that refused an existing
    run with ``ConfigError`` before still catch it).
    """


def os_reason(err: OSError) -> str:
    """The operating system's words for ``err`` (e.g. 'No space left on device')."""
    return err.strerror or (errno.errorcode.get(err.errno or 0) if err.errno else None) or str(err)


def partial_path(out: Path) -> Path:
    """``<out>.partial``: where ``out`` is written until it is complete."""
    return out.with_name(out.name + PARTIAL_SUFFIX)


def _lock_path(out: Path) -> Path:
    return out.with_name(out.name + LOCK_SUFFIX)


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``path`` through a temporary sibling and a rename: it is whole or absent."""
    tmp = path.with_name(f'.{path.name}.tmp-{os.getpid()}')
    try:
        with tmp.open('w', encoding='utf-8') as stream:
            stream.write(text)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def replace_folder(new: Path, final: Path) -> None:
    """Rename the folder ``new`` to ``final``; an existing ``final`` is moved aside, then removed.

    Between the two renames ``final`` is briefly absent, never half-written; when the second
    rename fails the old folder is put back.
    """
    if not final.exists():
        new.rename(final)
        return
    aside = final.with_name(f'{final.name}{REPLACED_SUFFIX}-{os.getpid()}')
    final.rename(aside)
    try:
        new.rename(final)
    except OSError:
        aside.rename(final)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _marker(folder: Path) -> dict[str, Any] | None:
    """The incomplete marker of ``folder``, or None; an unreadable marker still marks it."""
    path = folder / INCOMPLETE_FILE
    if not path.is_file():
        return None
    try:
        document = json.loads(path.read_text(encoding='utf-8'))
    except (OSError, ValueError):
        return {}
    return document if isinstance(document, dict) else {}


def _is_alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _describe_marker(marker: dict[str, Any]) -> str:
    """'train, pid 123 on host, started 2025-01-01 12:00:00, interrupted' from a marker."""
    command = marker.get('command', 'a command')
    started = marker.get('started_unix_s')
    when = (
        time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(started))
        if isinstance(started, (int, float))
        else 'at an unknown time'
    )
    pid = marker.get('pid')
    same_host = marker.get('host') == platform.node()
    state = 'still running' if same_host and _is_alive(pid) else 'interrupted'
    host = f' on {marker["host"]}' if marker.get('host') else ''
    return f'{command}, pid {pid}{host}, started {when}, {state}'


def incomplete_reason(folder: Path) -> str | None:
    """Why ``folder`` is not a complete result, or None when nothing says so.

    Incomplete: it holds the marker of a command still writing it or interrupted (its name ends
    in ``.partial`` then), or it is absent while ``<folder>.partial`` exists.
    """
    folder = Path(folder)
    marker = _marker(folder)
    if marker is not None:
        return f'{folder}: incomplete ({_describe_marker(marker)})'
    partial = partial_path(folder)
    if not folder.exists() and partial.is_dir():
        marker = _marker(partial) or {}
        return (
            f'{folder}: does not exist; only {partial} does, an incomplete result '
            f'({_describe_marker(marker)})'
        )
    return None


def _holds(folder: Path) -> str | None:
    """What kind of id_learning result ``folder`` holds; None when it is empty.

    Raises:
        OutputError: it holds something else (never replaced, even with --force).
    """
    names = {entry.name for entry in folder.iterdir()}
    if not names:
        return None
    found = [f'{what} already ({name})' for name, what in RESULT_FILES.items() if name in names]
    if not found:
        shown = ', '.join(sorted(names)[:3]) + (', ...' if len(names) > 3 else '')
        raise OutputError(
            f'{folder}: holds files that are not an id_learning result ({shown}); it is never '
            'replaced, not even with --force: choose another --out'
        )
    return found[0]


def check_output(
    out: Path, *, force: bool = False, inputs: Sequence[Path] = (), is_locked: bool = False
) -> Path:
    """Refuse an ``out`` that cannot or must not be written; returns the folder to write.

    A symbolic link to a folder stands for that folder. ``is_locked``: the caller holds the lock,
    so a partial folder there is left by a writer that is gone, whatever its marker says (before
    the lock, a writer still running is left for the lock to name).

    Raises:
        OutputError: ``out`` is a dangling link or not a folder; it is (or holds) an input of
            the command; it holds a result and ``force`` is not set; it holds something that is
            not a result; an interrupted result is beside it and ``force`` is not set.
    """
    out = Path(out)
    if out.is_symlink():
        if not out.exists():
            raise OutputError(
                f'{out}: is a symbolic link to {os.readlink(out)}, which does not exist; '
                'point --out at a folder'
            )
        out = out.resolve()
    if out.exists() and not out.is_dir():
        raise OutputError(f'{out}: exists and is not a folder; point --out at a folder')
    resolved = out.resolve()
    for given in inputs:
        source = Path(given).resolve()
        if source == resolved or resolved in source.parents:
            what = 'is' if source == resolved else f'holds {source},'
            raise OutputError(
                f'{out}: {what} an input of this command; it is never replaced, not even with '
                '--force: choose another --out'
            )
    if out.is_dir():
        try:
            held = _holds(out)
        except OSError as err:
            raise OutputError(f'{out}: {os_reason(err)}') from err
        if held is not None and not force:
            raise OutputError(
                f'{out}: holds {held}; choose another --out, or pass --force to replace it'
            )
    partial = partial_path(out)
    if partial.exists() and not force:
        marker = _marker(partial) if partial.is_dir() else None
        what = f' ({_describe_marker(marker)})' if marker is not None else ''
        if is_locked or marker is None or not _is_alive(marker.get('pid')):
            raise OutputError(
                f'{partial}: an incomplete result is there{what}; pass --force to replace it, '
                'or choose another --out'
            )
    return out


@dataclass
class ResultFolder:
    """A result folder being written.

    Attributes:
        out: where the result will be once complete.
        work: where it is written meanwhile (``<out>.partial``).
        keep: keep ``work`` when the command fails (set once it holds something worth keeping).
    """

    out: Path
    work: Path
    keep: bool = False


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold ``<out>.lock`` (flock, not waiting); removed on release.

    Raises:
        OutputError: another process holds it (named by its pid), or it cannot be created.
    """
    path = _lock_path(out)
    for _ in range(5):  # a holder may remove the file between our open and our flock
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise OutputError(f'{path}: {os_reason(err)} (locking {out})') from err
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 64).decode(errors='replace').strip() or 'unknown'
            os.close(fd)
            raise OutputError(
                f'{out}: another process (pid {holder}) is writing it ({path} is locked); '
                'wait for it to finish, or choose another --out'
            ) from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    else:
        raise OutputError(f'{path}: could not be locked (it kept being replaced)')
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f'{os.getpid()}\n'.encode())
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)


def _start(out: Path, command: str) -> Path:
    """A fresh ``<out>.partial`` with its marker (an interrupted one is removed first)."""
    work = partial_path(out)
    if work.is_symlink() or work.is_file():
        work.unlink()
    elif work.exists():
        _holds(work)  # never remove what is not ours
        shutil.rmtree(work)
    work.mkdir()
    marker = {
        'format': INCOMPLETE_FORMAT,
        'command': command,
        'out': str(out),
        'pid': os.getpid(),
        'host': platform.node(),
        'started_unix_s': time.time(),
    }
    write_text_atomic(work / INCOMPLETE_FILE, json.dumps(marker, indent=1) + '\n')
    return work


def _failed(folder: ResultFolder, err: OSError) -> OutputError:
    """One line for a write failure: the path, the OS's reason, what is left where."""
    path = err.filename if err.filename is not None else folder.work
    kept = (
        f'; what was written so far is in {folder.work}'
        if folder.keep and folder.work.exists()
        else f'; nothing is left at {folder.out}'
    )
    return OutputError(f'{path}: {os_reason(err)} (writing {folder.out}){kept}')


@contextlib.contextmanager
def result_folder(
    out: Path,
    *,
    command: str,
    force: bool = False,
    inputs: Sequence[Path] = (),
) -> Iterator[ResultFolder]:
    """Write a result folder whole or not at all; yields where to write (``.work``).

    Args:
        out: the result folder (``--out``); its parent folders are created.
        command: the command writing it, for the incomplete marker and messages.
        force: replace an existing result (never an input, never what is not a result).
        inputs: folders and files the command reads; ``out`` may not be or hold one.

    Raises:
        OutputError: ``out`` is refused (``check_output``), another process writes it, or a
            write failed (the path and the OS's reason).
    """
    out = check_output(out, force=force, inputs=inputs)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(
            f'{out.parent}: {os_reason(err)} (creating the folder of {out})'
        ) from err
    with _locked(out):
        out = check_output(out, force=force, inputs=inputs, is_locked=True)  # again, now ours
        folder = ResultFolder(out, partial_path(out))
        try:
            folder.work = _start(out, command)
            yield folder
            (folder.work / INCOMPLETE_FILE).unlink()
            replace_folder(folder.work, out)
        except BaseException as err:
            if not folder.keep:
                shutil.rmtree(folder.work, ignore_errors=True)
            if isinstance(err, OSError):
                raise _failed(folder, err) from err
            raise
