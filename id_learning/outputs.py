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
  renamed in, the old one removed. Only a result of the same kind (``folder_holds``) or an
  empty folder is replaced; never an input of the command, nor a folder holding or inside one.

Bags (``check_bag_output``), sweep folders (``check_kind``) and single files such as plots
(``check_file_output``) pass the same rule before any work starts.

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
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from id_learning.errors import ConfigError

__all__ = [
    'COMMAND_KINDS',
    'INCOMPLETE_FILE',
    'KINDS',
    'LOCK_SUFFIX',
    'PARTIAL_SUFFIX',
    'Holding',
    'OutputError',
    'ResultFolder',
    'check_bag_output',
    'check_file_output',
    'check_kind',
    'check_output',
    'check_target',
    'folder_holds',
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
#: The kinds of output, with how messages name them.
KINDS = {
    'run': 'a train run',
    'evaluation': 'an evaluation',
    'closed-loop': 'a closed-loop result',
    'diagnosis': 'a diagnosis',
    'demo': 'a demo',
    'bag': 'a bag',
    'sweep': 'a sweep',
}
#: The document saying a folder holds a result of a kind; first match wins (a run has metrics).
RESULT_KINDS = {
    'run.json': 'run',
    'summary.md': 'demo',
    'closed_loop.json': 'closed-loop',
    'effects.json': 'diagnosis',
    'metrics.json': 'evaluation',
    INCOMPLETE_FILE: 'run',
}
#: The kind each result-writing command writes.
COMMAND_KINDS = {
    'train': 'run',
    'evaluate': 'evaluation',
    'closed-loop': 'closed-loop',
    'diagnose': 'diagnosis',
    'demo': 'demo',
}
#: What a bag folder may hold besides its .mcap files: the twin's ground truth and config.
BAG_EXTRAS = frozenset({'metadata.yaml', 'ground_truth.json', 'ground_truth.npz',
                        'twin_config.yaml'})  # fmt: skip
#: What a sweep folder holds (``training.sweep``): the study, the best settings, the plots.
SWEEP_FILES = frozenset({'best.yaml', 'optimisation_history.png', 'parameter_importances.png'})


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


@dataclass(frozen=True)
class Holding:
    """What a folder holds, as its files say: what a command may replace is its own kind.

    Attributes:
        kind: a key of ``KINDS``, ``'empty'``, ``'torn bag'`` (for ``bag recover``) or
            ``'foreign'``.
        evidence: the file(s) that say so, for messages.
    """

    kind: str
    evidence: str = ''

    def describe(self) -> str:
        """'a train run (run.json)', 'files that are not ... (a, b)': for one-line messages."""
        if self.kind == 'empty':
            return 'nothing'
        if self.kind == 'torn bag':
            return f'a torn bag ({self.evidence} without metadata.yaml; bag recover rebuilds it)'
        if self.kind == 'foreign':
            return f'files that are not an id_learning result or a bag ({self.evidence})'
        return f'{KINDS[self.kind]} ({self.evidence})'


def _shown(names: Sequence[str]) -> str:  # the first three, for one-line messages
    return ', '.join(sorted(names)[:3]) + (', ...' if len(names) > 3 else '')


def _marker_kind(folder: Path) -> str:
    """The kind an incomplete marker's command writes ('run' for an unknown command)."""
    command = (_marker(folder) or {}).get('command')
    return COMMAND_KINDS.get(command, 'run') if isinstance(command, str) else 'run'


def folder_holds(folder: Path) -> Holding:
    """What ``folder`` holds by its files: a result of one kind, a bag, a sweep, or else.

    Raises:
        OSError: ``folder`` cannot be listed.
    """
    names = [entry.name for entry in Path(folder).iterdir()]
    if not names:
        return Holding('empty')
    for name, kind in RESULT_KINDS.items():
        if name in names:
            return Holding(_marker_kind(folder) if name == INCOMPLETE_FILE else kind, name)
    mcap = [name for name in names if name.endswith(('.mcap', '.mcap.damaged'))]
    others = [name for name in names if name not in mcap and name not in BAG_EXTRAS]
    if mcap and not others:
        if 'metadata.yaml' in names:
            return Holding('bag', f'metadata.yaml, {_shown(mcap)}')
        return Holding('torn bag', _shown(mcap))
    sweep = [name for name in names if name in SWEEP_FILES or name.startswith('sweep.db')]
    if len(sweep) == len(names) and {'sweep.db', 'best.yaml'} & set(names):
        return Holding('sweep', _shown(sweep))
    return Holding('foreign', _shown(others or names))


def _refuse_any_but_results(folder: Path, force: bool) -> None:
    """Without a kind to match: any result is replaced with ``force``, nothing else ever."""
    held = folder_holds(folder)
    if held.kind == 'empty':
        return
    if held.kind not in COMMAND_KINDS.values():
        raise OutputError(
            f'{folder}: holds {held.describe()}; it is never replaced, not even with '
            '--force: choose another --out'
        )
    if not force:
        raise OutputError(
            f'{folder}: holds {KINDS[held.kind]} already ({held.evidence}); choose another '
            '--out, or pass --force to replace it'
        )


def _probe_parent(out: Path) -> None:
    """Refuse an ``out`` whose parent cannot be created or written (the OS's reason)."""
    parent = out.parent
    while not parent.exists():
        if parent.is_symlink() or parent == parent.parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise OutputError(f'{out}: {parent} is a file, not a folder; choose another path')
    try:
        fd, probe = tempfile.mkstemp(prefix='.id_learning-probe-', dir=parent)
    except OSError as err:
        raise OutputError(f'{out}: cannot write in {parent}: {os_reason(err)}') from err
    os.close(fd)
    os.unlink(probe)


def _refuse_inputs(out: Path, inputs: Sequence[Path]) -> None:
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
            'not even with --force: choose another --out'
        )


def check_target(out: Path, *, inputs: Sequence[Path] = (), folder: bool = True) -> Path:
    """What every output path passes before any work: returns the path to write.

    Raises:
        OutputError: a dangling link; a file where a folder is expected (``folder``) or the
            reverse; ``out`` is, holds or lies inside an input; its parent cannot be written.
    """
    out = Path(out)
    if out.is_symlink():
        if not out.exists():
            raise OutputError(
                f'{out}: is a symbolic link to {os.readlink(out)}, which does not exist; '
                'point it at a folder'
            )
        out = out.resolve()
    if folder and out.exists() and not out.is_dir():
        raise OutputError(f'{out}: exists and is not a folder but a file; name a folder to write')
    if not folder and out.is_dir():
        raise OutputError(f'{out}: is a folder; name a file to write')
    _refuse_inputs(out, inputs)
    _probe_parent(out)
    return out


def check_kind(out: Path, kind: str, *, force: bool, flag: str = '--force') -> None:
    """Refuse a folder ``out`` that holds something ``force`` may not replace.

    Only an empty folder, or (with ``force``) one of the same ``kind``, is written; a sweep
    folder is added to, so for ``kind='sweep'`` a sweep is taken without ``force``.

    Raises:
        OutputError: names ``out``, what it holds and what ``flag`` replaces.
    """
    if not out.is_dir():
        return
    try:
        held = folder_holds(out)
    except OSError as err:
        raise OutputError(f'{out}: {os_reason(err)}') from err
    if held.kind == 'empty' or (held.kind == kind and (force or kind == 'sweep')):
        return
    if held.kind == kind:
        raise OutputError(
            f'{out}: holds {KINDS[kind]} already ({held.evidence}); choose another path, or '
            f'pass {flag} to replace it'
        )
    raise OutputError(
        f'{out}: holds {held.describe()}; {flag} replaces only {KINDS[kind]}: choose another path'
    )


def check_bag_output(
    out: Path, *, overwrite: bool = False, inputs: Sequence[Path] = (), flag: str = '--force'
) -> Path:
    """Refuse a bag folder that cannot or must not be written; returns the folder to write.

    A bag replaces only a bag (``metadata.yaml`` and ``.mcap`` files, nothing foreign) or an
    empty folder, and only with ``overwrite`` (``flag`` names it in messages).

    Raises:
        OutputError: as ``check_target`` and ``check_kind`` say.
    """
    out = check_target(out, inputs=inputs)
    check_kind(out, 'bag', force=overwrite, flag=flag)
    return out


def check_file_output(
    out: Path,
    *,
    force: bool = False,
    inputs: Sequence[Path] = (),
    suffixes: Sequence[str] = (),
) -> Path:
    """Refuse a file that cannot or must not be written; returns the file to write.

    ``suffixes``: the ones accepted (lower case, with the dot), when given. An existing file is
    replaced only with ``force``; never one inside a result folder or a bag (another command's).
    """
    out = check_target(Path(out), inputs=inputs, folder=False)
    if suffixes and out.suffix.lower() not in suffixes:
        raise OutputError(
            f'{out}: not a file type that can be written here; use one of {", ".join(suffixes)}'
        )
    if out.parent.is_dir():
        try:
            held = folder_holds(out.parent)
        except OSError as err:
            raise OutputError(f'{out.parent}: {os_reason(err)}') from err
        if held.kind not in ('empty', 'foreign'):
            raise OutputError(
                f'{out}: {out.parent} holds {held.describe()}; write the file elsewhere'
            )
    if out.exists() and not force:
        raise OutputError(f'{out}: exists; choose another path, or pass --force to replace it')
    return out


def check_output(
    out: Path,
    *,
    force: bool = False,
    inputs: Sequence[Path] = (),
    is_locked: bool = False,
    kind: str | None = None,
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
    out = check_target(out, inputs=inputs)
    try:
        if kind is not None:
            check_kind(out, kind, force=force)
        elif out.is_dir():
            _refuse_any_but_results(out, force)
    except OSError as err:
        raise OutputError(f'{out}: {os_reason(err)}') from err
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
        _refuse_any_but_results(work, force=True)  # never remove what is not ours
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
        force: replace an existing result of the kind ``command`` writes (``COMMAND_KINDS``;
            any result for another command), never an input, never what is not a result.
        inputs: folders and files the command reads; ``out`` may not be, hold or lie in one.

    Raises:
        OutputError: ``out`` is refused (``check_output``), another process writes it, or a
            write failed (the path and the OS's reason).
    """
    kind = COMMAND_KINDS.get(command)
    out = check_output(out, force=force, inputs=inputs, kind=kind)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(
            f'{out.parent}: {os_reason(err)} (creating the folder of {out})'
        ) from err
    with _locked(out):
        out = check_output(out, force=force, inputs=inputs, is_locked=True, kind=kind)  # ours
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
