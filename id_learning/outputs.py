"""Result folders written whole or not at all: a partial sibling, a lock, one rename at the end.

Every command that writes a result folder (``train``, ``evaluate``, ``closed-loop``,
``diagnose``, ``demo``) writes it through ``result_folder``:

- ``<out>.lock`` (a sibling) is locked with ``fcntl.flock``, without waiting: a second writer to
  the same ``<out>`` is refused at once, naming the holder's pid;
- everything is written into ``<out>.partial``, which holds ``incomplete.json`` (the command, pid,
  host and start time) until it is complete, so that a folder left by a killed command says what
  it is;
- when complete, the marker is replaced by the manifest (``.id_learning.json``, what the command
  wrote) and ``<out>.partial`` renamed to ``<out>``. An existing result there is replaced only
  with ``force``, and then atomically: moved aside, the new one renamed in, the old one removed.
  Only a result of the same kind holding nothing its manifest does not list
  (``id_learning.output_kinds``) or an empty folder is replaced; never an input of the command,
  nor a folder holding or inside one. Only a ``.partial`` folder holding the marker is ours.

Bags (``check_bag_output``), sweep folders (``check_kind``) and single files such as plots
(``check_file_output``) pass the same rule before any work starts (``check_target``): there a
name longer than the file system takes (``NAME_MAX``, less ``NAME_RESERVE`` for the last, which
gets suffixes) or a path longer than ``PATH_MAX`` is one line naming the path, and so is any
error of the operating system while the path is looked at. Messages name the option or
parameter that gave the path (``option``: ``--out``, ``--plot``, the recorder's ``output``).
A bag is locked the same way while it is written (``bag_output``, ``BagWriter``): a second
writer is refused naming the first. A replay holds the lock shared while it plays a bag
(``read_lock``): a writer that would replace the bag is refused naming the replay
(``id_learning.output_lock``).

A failure while writing (disk full, a file size limit, no permission) raises ``OutputError``
naming the path and the operating system's reason; nothing is left under ``<out>``, and the
partial folder is removed unless the writer asked to keep it (a training run keeps the models it
has fitted). Consumers ask ``incomplete_reason`` whether a folder they read is complete.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import platform
import shutil
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from id_learning.output_kinds import (
    COMMAND_KINDS,
    INCOMPLETE_FILE,
    KINDS,
    LOCK_SUFFIX,
    MANIFEST_FILE,
    NAME_RESERVE,
    PARTIAL_SUFFIX,
    Holding,
    OutputError,
    check_kind,
    folder_holds,
    foreign_entries,
    make_parent,
    os_reason,
    read_marker,
    refuse_any_but_results,
    refuse_inside_results,
    refuse_long_names,
    refuse_unwritten,
    write_manifest,
)
from id_learning.output_lock import locked, named_path, output_lock, read_lock

__all__ = [
    'COMMAND_KINDS',
    'INCOMPLETE_FILE',
    'KINDS',
    'LOCK_SUFFIX',
    'MANIFEST_FILE',
    'NAME_RESERVE',
    'PARTIAL_SUFFIX',
    'Holding',
    'OutputError',
    'ResultFolder',
    'bag_output',
    'check_bag_output',
    'check_file_output',
    'check_kind',
    'check_output',
    'check_target',
    'folder_holds',
    'foreign_entries',
    'incomplete_reason',
    'named_path',
    'os_reason',
    'output_lock',
    'partial_path',
    'read_lock',
    'refuse_long_names',
    'replace_folder',
    'result_folder',
    'write_text_atomic',
]

_LOG = logging.getLogger(__name__)

#: Where a replaced result waits, for a moment, to be removed.
REPLACED_SUFFIX = '.replaced'
INCOMPLETE_FORMAT = 'id_learning.incomplete/1'


def partial_path(out: Path) -> Path:
    """``<out>.partial``: where ``out`` is written until it is complete."""
    return named_path(out).with_name(named_path(out).name + PARTIAL_SUFFIX)


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
    marker = read_marker(folder)
    if marker is not None:
        return f'{folder}: incomplete ({_describe_marker(marker)})'
    partial = partial_path(folder)
    marker = read_marker(partial) if partial.is_dir() else None
    if not folder.exists() and marker is not None:
        return (
            f'{folder}: does not exist; only {partial} does, an incomplete result '
            f'({_describe_marker(marker)})'
        )
    return None


def _probe_parent(out: Path, option: str) -> None:
    """Refuse an ``out`` whose parent cannot be created or written (the OS's reason)."""
    parent = out.parent
    while not parent.exists():
        if parent.is_symlink() or parent == parent.parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise OutputError(f'{out}: {parent} is a file, not a folder; choose another {option}')
    try:
        fd, probe = tempfile.mkstemp(prefix='.id_learning-probe-', dir=parent)
    except OSError as err:
        raise OutputError(f'{out}: cannot write in {parent}: {os_reason(err)}') from err
    os.close(fd)
    os.unlink(probe)


def _refuse_inputs(out: Path, inputs: Sequence[Path], option: str) -> None:
    """Refuse an ``out`` that is, holds or lies inside an input of the command."""
    resolved = out.resolve()
    for given in inputs:
        source = Path(given).resolve()
        if source == resolved:
            where = 'is'
        elif resolved in source.parents:
            where = f'holds {source},'
        elif source in resolved.parents:
            where = f'lies inside {source},'
        else:
            continue
        raise OutputError(
            f'{out}: {where} an input of this command; it is never replaced or written into, '
            f'not even with --force: choose another {option}'
        )


def check_target(
    out: Path, *, inputs: Sequence[Path] = (), folder: bool = True, option: str = '--out'
) -> Path:
    """What every output path passes before any work: returns the path to write.

    ``option``: the option or parameter that gave ``out``, as messages name it.

    Raises:
        OutputError: a name or the path too long for the file system (``refuse_long_names``);
            a dangling link; a file where a folder is expected (``folder``) or the reverse;
            ``out`` is, holds or lies inside an input; its parent cannot be written; the
            operating system refuses to look at it (its reason).
    """
    out = Path(out)
    refuse_long_names(out, option)
    try:
        return _check_target(out, inputs, folder, option)
    except OSError as err:  # e.g. a name this file system takes shorter than it says
        raise OutputError(f'{out}: {os_reason(err)}; choose another {option}') from err


def _check_target(out: Path, inputs: Sequence[Path], folder: bool, option: str) -> Path:
    if '..' in out.parts or not out.name:  # 'a/../b' is b: never create a; '.': its name
        out = out.resolve()
    if out.is_symlink():
        if not out.exists():  # nothing is written through it: it may point into a lost disk
            target = os.readlink(out)
            if not Path(target).is_absolute():
                target += f' ({out.resolve()})'
            fix = 'create that folder, remove' if folder else 'remove'
            raise OutputError(
                f'{out}: is a symbolic link to {target}, which does not exist (a dangling '
                f'link); {fix} the link or choose another {option}'
            )
        out = out.resolve()
    if folder and out.exists() and not out.is_dir():
        raise OutputError(
            f'{out}: exists and is not a folder but a file; name a folder for {option}'
        )
    if not folder and out.is_dir():
        raise OutputError(f'{out}: is a folder; name a file for {option}')
    _refuse_inputs(out, inputs, option)
    refuse_inside_results(out, option, file=not folder)
    _probe_parent(out, option)
    return out


def check_bag_output(
    out: Path,
    *,
    overwrite: bool = False,
    inputs: Sequence[Path] = (),
    flag: str = '--force',
    option: str = '--out',
) -> Path:
    """Refuse a bag folder that cannot or must not be written; returns the folder to write.

    A bag replaces only a bag (``metadata.yaml`` and ``.mcap`` files, nothing foreign) or an
    empty folder, and only with ``overwrite`` (``flag`` names it in messages, ``option`` the
    option or parameter that gave ``out``). A bag another process is writing (its
    ``<out>.lock`` held) is refused naming that process: in progress, it looks torn. Probing
    takes the lock for a moment (a disk already full is refused here).

    Raises:
        OutputError: as ``check_target`` and ``check_kind`` say; another process writes ``out``.
    """
    out = check_target(out, inputs=inputs, option=option)
    if out.parent.is_dir():
        with output_lock(out, option=option):
            pass
    check_kind(out, 'bag', force=overwrite, flag=flag)
    return out


@contextlib.contextmanager
def bag_output(
    out: Path,
    *,
    overwrite: bool = False,
    inputs: Sequence[Path] = (),
    flag: str = '--force',
    option: str = '--out',
) -> Iterator[Path]:
    """Hold ``<out>.lock`` while a bag is written to ``out``; yields the folder to write.

    A command holds it from its checks to its last file (the twin's ground truth after the bag),
    so a second writer of the same bag is refused at once, naming the first's pid, instead of
    finding a bag in progress that looks torn. ``BagWriter`` takes the same lock (it goes on
    under its command's). The parent folders of ``out`` are created.

    Raises:
        OutputError: as ``check_bag_output`` says; another process writes ``out``; the lock
            cannot be created.
    """
    out = check_bag_output(out, overwrite=overwrite, inputs=inputs, flag=flag, option=option)
    make_parent(out)
    with output_lock(out, option=option):
        yield check_bag_output(out, overwrite=overwrite, inputs=inputs, flag=flag, option=option)


def _check_suffix(path: Path, suffixes: Sequence[str]) -> None:
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(
            f'{path}: not a file type that can be written here; use one of {", ".join(suffixes)}'
        )


def check_file_output(
    out: Path,
    *,
    force: bool = False,
    inputs: Sequence[Path] = (),
    suffixes: Sequence[str] = (),
    option: str = '--plot',
) -> Path:
    """Refuse a file that cannot or must not be written; returns the file to write.

    ``suffixes``: the ones accepted (lower case, with the dot), when given. An existing file is
    replaced only with ``force``; never one inside a result folder or a bag (another command's).
    ``option``: the option that gave ``out`` (the tool's one file output is ``inspect --plot``).
    """
    refuse_long_names(Path(out), option)
    if not Path(out).is_dir():  # a folder is named as such (check_target)
        _check_suffix(Path(out), suffixes)  # the name given, then the file a link points to
    out = check_target(Path(out), inputs=inputs, folder=False, option=option)
    _check_suffix(out, suffixes)
    if out.exists() and not force:
        raise OutputError(f'{out}: exists; choose another {option}, or pass --force to replace it')
    return out


def check_output(
    out: Path,
    *,
    force: bool = False,
    inputs: Sequence[Path] = (),
    is_locked: bool = False,
    kind: str | None = None,
    option: str = '--out',
) -> Path:
    """Refuse an ``out`` that cannot or must not be written; returns the folder to write.

    A symbolic link to a folder stands for that folder. ``kind``: the kind of result written
    (a key of ``KINDS``): ``force`` replaces only that kind; None: any result. ``is_locked``:
    the caller holds the lock, so a partial folder there is left by a writer that is gone,
    whatever its marker says (before the lock, a writer still running is left for the lock to
    name).

    Raises:
        OutputError: as ``check_target`` and ``check_kind`` say; or an interrupted result is
            beside it and ``force`` is not set.
    """
    out = check_target(out, inputs=inputs, option=option)
    try:
        if kind is not None:
            check_kind(out, kind, force=force)
        elif out.is_dir():
            refuse_any_but_results(out, force, option)
    except OSError as err:
        raise OutputError(f'{out}: {os_reason(err)}') from err
    partial = partial_path(out)
    if not (partial.exists() or partial.is_symlink()):
        return out
    marker = _partial_marker(partial, option)
    if not force and (is_locked or not _is_alive(marker.get('pid'))):
        raise OutputError(
            f'{partial}: an incomplete result is there ({_describe_marker(marker)}); pass '
            f'--force to replace it, or choose another {option}'
        )
    return out


def _partial_marker(partial: Path, option: str = '--out') -> dict[str, Any]:
    """The marker of ``partial``; refuses a ``.partial`` that is not a folder holding one."""
    marker = None if partial.is_symlink() or not partial.is_dir() else read_marker(partial)
    if marker is None:
        what = 'a folder without ' + INCOMPLETE_FILE if partial.is_dir() else 'not a folder'
        raise OutputError(
            f'{partial}: exists and is not an incomplete result of id_learning ({what}); it is '
            f'never replaced, not even with --force: move it, or choose another {option}'
        )
    return marker


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


def _start(out: Path, command: str, option: str) -> Path:
    """A fresh ``<out>.partial`` with its marker (an interrupted one is removed first)."""
    work = partial_path(out)
    if work.exists() or work.is_symlink():
        _partial_marker(work, option)  # never remove what is not ours
        refuse_any_but_results(work, True, option)
        refuse_unwritten(work, option)
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
    option: str = '--out',
) -> Iterator[ResultFolder]:
    """Write a result folder whole or not at all; yields where to write (``.work``).

    Args:
        out: the result folder (``--out``); its parent folders are created.
        command: the command writing it, for the incomplete marker and messages.
        force: replace an existing result of the kind ``command`` writes (``COMMAND_KINDS``;
            any result for another command), never an input, never what is not a result.
        inputs: folders and files the command reads; ``out`` may not be, hold or lie in one.
        option: the option that gave ``out``, as messages name it.

    Raises:
        OutputError: ``out`` is refused (``check_output``), another process writes it, or a
            write failed (the path and the OS's reason).
    """
    kind = COMMAND_KINDS.get(command)
    out = check_output(out, force=force, inputs=inputs, kind=kind, option=option)
    make_parent(out)
    with locked(out, option):  # not output_lock: a result has one writer, even in one thread
        out = check_output(  # ours
            out, force=force, inputs=inputs, is_locked=True, kind=kind, option=option
        )
        try:
            # Ours from here: removed on failure.
            folder = ResultFolder(out, _start(out, command, option))
        except OSError as err:
            raise OutputError(f'{partial_path(out)}: {os_reason(err)} (starting {out})') from err
        try:
            yield folder
            (folder.work / INCOMPLETE_FILE).unlink()
            write_manifest(folder.work, command)
            replace_folder(folder.work, out)
        except BaseException as err:
            if not folder.keep:
                shutil.rmtree(folder.work, ignore_errors=True)
            # A closed standard output (``| head``) is no failure of the folder: the command
            # ends quietly (``cli.main``).
            if isinstance(err, OSError) and not isinstance(err, BrokenPipeError):
                raise _failed(folder, err) from err
            raise
