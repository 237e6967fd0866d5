"""What a folder holds, and what a command may replace: kinds of result, manifests, bags.

A result folder says its kind by one document (``RESULT_KINDS``); once complete it also holds
``.id_learning.json``, the manifest listing the entries its command wrote. A bag lists its files
in ``metadata.yaml``; the twin's ground-truth files are known (``BAG_EXTRAS``). ``--force``
replaces a folder of its own kind only when it holds nothing else: an entry neither listed nor
known is foreign, and a folder holding one is never replaced. A result written before manifests
existed is judged by its kind alone. An output's names must fit the file system
(``refuse_long_names``), the last with room for the names made from it (``NAME_RESERVE``).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from id_learning.config_io import read_capped
from id_learning.errors import ConfigError

__all__ = [
    'BAG_EXTRAS',
    'COMMAND_KINDS',
    'INCOMPLETE_FILE',
    'KINDS',
    'LOCK_SUFFIX',
    'MANIFEST_FILE',
    'NAME_RESERVE',
    'PARTIAL_SUFFIX',
    'RESULT_KINDS',
    'SWEEP_FILES',
    'WRITTEN_ENTRIES',
    'Holding',
    'OutputError',
    'check_kind',
    'folder_holds',
    'foreign_entries',
    'make_parent',
    'os_reason',
    'read_marker',
    'refuse_any_but_results',
    'refuse_inside_results',
    'refuse_long_names',
    'refuse_unwritten',
    'write_manifest',
    'writer_of',
]

#: Where a result is written until it is complete (``outputs.result_folder``).
PARTIAL_SUFFIX = '.partial'
#: The sibling a writer of ``<out>`` holds locked while it writes (``outputs.output_lock``).
LOCK_SUFFIX = '.lock'

INCOMPLETE_FILE = 'incomplete.json'
#: The manifest of a complete result folder: its command, kind and top-level entries.
MANIFEST_FILE = '.id_learning.json'
MANIFEST_FORMAT = 'id_learning.manifest/1'
#: Bytes the last name of an output must leave free for the names made from it: the longest
#: is ``<name>.replaced-<pid>`` (a replaced result; 7 digits: Linux's largest pid) and a bag's
#: ``<name>_<k>.mcap.damaged``; ``<name>.partial``, ``<name>.lock`` and a file's
#: ``.<name>.tmp-<pid>`` are shorter.
NAME_RESERVE = 20
#: Where the file system cannot be asked (no pathconf): Linux's limits [bytes].
_DEFAULT_NAME_MAX, _DEFAULT_PATH_MAX = 255, 4096
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
#: The top-level entries the result-writing commands write (all kinds together): what an
#: interrupted result's ``.partial`` folder may hold before ``--force`` removes it.
WRITTEN_ENTRIES = frozenset({
    INCOMPLETE_FILE, MANIFEST_FILE, 'run.json', 'metrics.json', 'report.md', 'models', 'model',
    'run', 'closed_loop', 'effects.json', 'summary.json', 'summary.md', 'online_check.json',
    'closed_loop.json', 'closed_loop.png', 'rmse_per_joint.png', 'abs_error_boxplot.png',
    'dissipative_axis1.png', 'torque_shares.png', 'torque_timeseries.png', 'excitation.png',
    'waterfall.png', 'residual_location.png', 'residual_time.png', 'error_spectra.png',
    'needed_error_spectra.png', 'torque_overlays', 'closed_loop_feed_forward.png',
})  # fmt: skip
#: What a bag folder may hold besides its .mcap files: the twin's ground truth and config.
BAG_EXTRAS = frozenset({'metadata.yaml', 'ground_truth.json', 'ground_truth.npz',
                        'twin_config.yaml', 'excitation.json', 'trajectory.csv'})  # fmt: skip
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


#: The most bytes read of a marker, a manifest or a bag's metadata.yaml when judging a folder:
#: ours are a few KiB; a larger one (or a device, a FIFO) is no valid one and is not read.
_MAX_JUDGED_BYTES = 4 * 2**20


def _judged_text(path: Path) -> str:
    """The text of a small file a folder is judged by; ConfigError or OSError when refused."""
    return read_capped(path, 'file', _MAX_JUDGED_BYTES, regular=True).decode('utf-8')


def read_marker(folder: Path) -> dict[str, Any] | None:
    """The incomplete marker of ``folder``, or None; an unreadable marker still marks it."""
    path = folder / INCOMPLETE_FILE
    if not path.is_file():
        return None
    try:
        document = json.loads(_judged_text(path))
    except (OSError, ValueError, ConfigError):
        return {}
    return document if isinstance(document, dict) else {}


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
    command = (read_marker(folder) or {}).get('command')
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


def write_manifest(folder: Path, command: str) -> None:
    """Record in ``folder`` what ``command`` wrote there: its top-level entries, and the kind.

    Raises:
        OSError: listing ``folder`` or writing the manifest failed.
    """
    entries = sorted(entry.name for entry in folder.iterdir() if entry.name != MANIFEST_FILE)
    document = {
        'format': MANIFEST_FORMAT,
        'command': command,
        'kind': COMMAND_KINDS.get(command, 'run'),
        'entries': entries,
    }
    (folder / MANIFEST_FILE).write_text(json.dumps(document, indent=1) + '\n', encoding='utf-8')


def _listed(document: object, key: str) -> set[str] | None:
    """The strings of ``document[key]`` (a list), or None when it is not such a list."""
    if not isinstance(document, dict):
        return None
    listed = document.get(key)
    if not isinstance(listed, list) or not all(isinstance(name, str) for name in listed):
        return None
    return set(listed)


def _manifest_entries(folder: Path) -> set[str] | None:
    """The entries the manifest of ``folder`` lists; None without one; empty when unreadable."""
    path = folder / MANIFEST_FILE
    if not path.exists():
        return None
    try:
        document = json.loads(_judged_text(path))
    except (OSError, ValueError, ConfigError):
        return set()
    return _listed(document, 'entries') or set()


def _bag_entries(folder: Path) -> set[str] | None:
    """The files a bag's ``metadata.yaml`` lists, with ``BAG_EXTRAS``; None when it lists none."""
    try:
        document = yaml.safe_load(_judged_text(folder / 'metadata.yaml'))
    except (OSError, ValueError, yaml.YAMLError, ConfigError):
        return None
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    listed = _listed(info, 'relative_file_paths')
    if listed is None:
        return None
    return set(BAG_EXTRAS) | {Path(name).parts[0] for name in listed if Path(name).parts}


def foreign_entries(folder: Path, kind: str) -> list[str]:
    """The entries of ``folder`` (of ``kind``) that its writer did not write, sorted.

    A result: those its manifest does not list; a bag: those neither its ``metadata.yaml`` lists
    nor known. None without a manifest or a list of files (written before they existed, or by
    another tool): then its kind alone decides.

    Raises:
        OSError: ``folder`` cannot be listed.
    """
    names = {entry.name for entry in folder.iterdir()}
    if kind not in (*COMMAND_KINDS.values(), 'bag'):
        return []
    listed = _bag_entries(folder) if kind == 'bag' else _manifest_entries(folder)
    if listed is None:
        return []
    return sorted(names - listed - {MANIFEST_FILE})


def _refuse_foreign(folder: Path, kind: str, flag: str) -> None:
    """Refuse replacing ``folder`` when it holds entries its writer did not write (named)."""
    foreign = foreign_entries(folder, kind)
    if foreign:
        source = 'metadata.yaml' if kind == 'bag' else MANIFEST_FILE
        raise OutputError(
            f'{folder}: holds {KINDS[kind]} and also {_shown(foreign)}, which its {source} does '
            f'not list; {flag} never deletes them: move them out, or choose another path'
        )


def refuse_any_but_results(folder: Path, force: bool, option: str = '--out') -> None:
    """Without a kind to match: any result is replaced with ``force``, nothing else ever.

    ``option``: the option that gave ``folder``, as messages name it.
    """
    held = folder_holds(folder)
    if held.kind == 'empty':
        return
    if held.kind not in COMMAND_KINDS.values():
        raise OutputError(
            f'{folder}: holds {held.describe()}; it is never replaced, not even with '
            f'--force: choose another {option}'
        )
    if not force:
        raise OutputError(
            f'{folder}: holds {KINDS[held.kind]} already ({held.evidence}); choose another '
            f'{option}, or pass --force to replace it'
        )
    _refuse_foreign(folder, held.kind, '--force')


def refuse_unwritten(work: Path, option: str = '--out') -> None:
    """Refuse removing an interrupted ``.partial`` that holds entries no command writes.

    ``option``: the option that gave the result's path, as the message names it.

    Raises:
        OutputError: names the folder and the entries (``WRITTEN_ENTRIES`` are ours).
        OSError: ``work`` cannot be listed.
    """
    stray = [entry.name for entry in work.iterdir() if entry.name not in WRITTEN_ENTRIES]
    if stray:
        raise OutputError(
            f'{work}: an incomplete result that also holds {_shown(stray)}, which no '
            'id_learning command writes; --force never deletes them: move them out, or '
            f'choose another {option}'
        )


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
    if held.kind == 'empty' or (held.kind == kind and kind == 'sweep'):
        return
    if held.kind == kind and force:
        try:
            _refuse_foreign(out, kind, flag)
        except OSError as err:
            raise OutputError(f'{out}: {os_reason(err)}') from err
        return
    if held.kind == kind:
        raise OutputError(
            f'{out}: holds {KINDS[kind]} already ({held.evidence}); choose another path, or '
            f'pass {flag} to replace it'
        )
    raise OutputError(
        f'{out}: holds {held.describe()}; {flag} replaces only {KINDS[kind]}: choose another path'
    )


def make_parent(out: Path) -> None:
    """Create the folder ``out`` goes into.

    Raises:
        OutputError: it cannot be created (the OS's reason).
    """
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(
            f'{out.parent}: {os_reason(err)} (creating the folder of {out})'
        ) from err


def _limits(out: Path) -> tuple[int, int]:
    """(NAME_MAX, PATH_MAX) [bytes] of the file system ``out`` would be written to."""
    existing = Path(os.path.abspath(out))
    while True:
        try:
            if existing.is_dir():
                break
        except OSError:
            pass
        if existing == existing.parent:
            break
        existing = existing.parent
    limits = []
    for name, default in (('PC_NAME_MAX', _DEFAULT_NAME_MAX), ('PC_PATH_MAX', _DEFAULT_PATH_MAX)):
        try:
            value = os.pathconf(existing, name)
        except (OSError, ValueError):
            value = -1
        limits.append(value if value > 0 else default)
    return limits[0], limits[1]


def _shorten(name: str, keep: int = 24) -> str:
    return name if len(name) <= keep + 3 else f'{name[:keep]}...'


def refuse_long_names(out: Path, option: str = '--out') -> None:
    """Refuse an output path the file system cannot hold, before anything touches it.

    Every name in it at most ``NAME_MAX`` bytes (the file system's), the last at most
    ``NAME_MAX - NAME_RESERVE`` (the names made from it: ``.partial``, ``.lock``, ...), and the
    whole path, absolute, at most ``PATH_MAX - NAME_RESERVE``.

    Raises:
        OutputError: one line naming the path, the name, its length and the limit, and
            ``option``.
    """
    out = Path(out)
    name_max, path_max = _limits(out)
    parts = [part for part in out.parts if part not in ('/', '.', '..')]
    for k, part in enumerate(parts):
        size = len(os.fsencode(part))
        last = k == len(parts) - 1
        limit = name_max - NAME_RESERVE if last else name_max
        if size > limit:
            beside = (
                f' (the file system takes {name_max}; {NAME_RESERVE} are kept for the '
                'names made from it, such as .partial and .lock)'
                if last
                else ''
            )
            raise OutputError(
                f'{out}: file name too long: {_shorten(part)!r} is {size} bytes, at most '
                f'{limit} can be written there{beside}; choose a shorter {option}'
            )
    size = len(os.fsencode(os.path.abspath(out)))
    if size > path_max - NAME_RESERVE:
        raise OutputError(
            f'{out}: path too long: {size} bytes as an absolute path, at most '
            f'{path_max - NAME_RESERVE} can be written there; choose a shorter {option}'
        )


def _being_written_here(folder: Path) -> bool:
    """Whether ``folder`` is a ``.partial`` result this process is writing (a demo's steps)."""
    if not folder.name.endswith(PARTIAL_SUFFIX):
        return False
    marker = read_marker(folder) if (folder / INCOMPLETE_FILE).is_file() else None
    return marker is not None and marker.get('pid') == os.getpid()


def _is_our_result(folder: Path) -> bool:
    """Whether ``folder`` says by our manifest or incomplete marker that a command wrote it."""
    try:
        manifest = json.loads(_judged_text(folder / MANIFEST_FILE))
    except (OSError, ValueError, ConfigError):
        manifest = None
    if isinstance(manifest, dict) and manifest.get('format') == MANIFEST_FORMAT:
        return True
    return (folder / INCOMPLETE_FILE).is_file() and read_marker(folder) is not None


def refuse_inside_results(out: Path, option: str, *, file: bool = False) -> None:
    """Refuse an ``out`` inside another command's result or a bag, at any depth.

    A result says so by its manifest or its incomplete marker, a bag by its files (metadata.yaml
    and storage, nothing else): a user's folder that merely holds a ``metrics.json`` or a few
    ``.mcap`` files is no result. A ``file`` (a plot) is held to more: in its own folder any
    result document or storage file, above it a ``run.json`` too. A result this process is
    writing is the exception: a command's steps write into it.
    """
    for depth, parent in enumerate(out.resolve().parents):
        try:
            held = folder_holds(parent) if parent.is_dir() else Holding('empty')
        except OSError as err:
            if depth == 0:
                raise OutputError(f'{parent}: {os_reason(err)}') from err
            continue  # an ancestor that cannot be listed says nothing
        if held.kind in ('empty', 'foreign') or _being_written_here(parent):
            continue
        if file:
            ours = {MANIFEST_FILE, INCOMPLETE_FILE, 'run.json'} & {
                e.name for e in parent.iterdir()
            }
            refused = not depth or held.kind in ('bag', 'torn bag') or bool(ours)
        else:
            refused = held.kind == 'bag' or _is_our_result(parent)
        if refused:
            raise OutputError(
                f'{out}: lies inside {parent}, which holds {held.describe()}; nothing is '
                f'written into another result or a bag: choose another {option}'
            )


def writer_of(folder: Path) -> str | None:
    """The pid (as its lock file says) of a process writing ``folder`` now, or None.

    Asked of a folder that looks torn: a bag or a result still being written is complete once
    its writer ends, and is neither damaged nor to be recovered.
    """
    folder = Path(os.path.abspath(folder))
    try:
        fd = os.open(folder.with_name(folder.name + LOCK_SUFFIX), os.O_RDONLY)
    except (OSError, ValueError):
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 64).decode(errors='replace').strip()
        return holder or 'unknown'
    except OSError:
        return None
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)
