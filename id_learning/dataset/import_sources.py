"""The log files an import reads: files as given, folders as the log files in them.

A folder is read without its subfolders: a subfolder may hold a log of its own, a backup or an
export, and which of them belong to this recording only the user knows. Nothing that looks like a
log is left out without a word, though: a file with a log suffix in the folder is read (and
refused when it is no log, naming it), and subfolders holding log files are named in a warning
with the way to import them (name them as sources too). Files with other suffixes (a mapping, a
README, a plot) are no logs and are passed over.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from id_learning.bag.distinct import check_distinct
from id_learning.dataset.import_readers import log_suffix
from id_learning.errors import DatasetError

__all__ = ['LOG_SUFFIXES', 'log_files']

logger = logging.getLogger(__name__)

#: The suffixes of files a folder contributes (also gzipped: ``.csv.gz``).
LOG_SUFFIXES = ('.csv', '.tsv', '.txt', '.dat', '.log', '.npz')
_NAMED = 5  # subfolders named in the warning, then a count


def _is_log(path: Path) -> bool:
    return path.is_file() and log_suffix(path) in LOG_SUFFIXES


def _logs_below(folder: Path) -> int:
    """Log files anywhere below ``folder`` (0 when it cannot be listed)."""
    try:
        return sum(1 for path in folder.rglob('*') if _is_log(path))
    except OSError:
        return 0


def _warn_subfolders(folder: Path, given: Sequence[Path]) -> None:
    """Name the subfolders of ``folder`` that hold log files and no source ``given``."""
    skipped = [
        (sub, n)
        for sub in sorted(folder.iterdir())
        if sub.is_dir()
        and not any(source.is_relative_to(sub.resolve()) for source in given)
        and (n := _logs_below(sub))
    ]
    if not skipped:
        return
    named = ', '.join(f'{sub.name}/ ({n} log file{"s" if n > 1 else ""})' for sub, n in skipped)
    if len(skipped) > _NAMED:
        named = ', '.join(named.split(', ')[:_NAMED]) + f', ... ({len(skipped)} in all)'
    logger.warning(
        '%s: skipped %d subfolder%s holding log files: %s; a folder is read without its '
        'subfolders: give a subfolder as a source too (e.g. %s) to import its logs',
        folder,
        len(skipped),
        's' if len(skipped) > 1 else '',
        named,
        skipped[0][0],
    )


def log_files(sources: Sequence[Path | str]) -> list[Path]:
    """The log files named: files as given, folders as their log files in name order.

    A folder's subfolders are not read; those holding log files are named in a warning, unless
    they are (or hold) sources themselves.

    Raises:
        DatasetError: a source does not exist, or a folder holds no log file (it names the
            subfolders that do).
        ConfigError: one log given twice (same file, or identical bytes), naming it.
    """
    files: list[Path] = []
    given = [Path(source).resolve() for source in sources]
    for source in map(Path, sources):
        if source.is_dir():
            found = sorted(p for p in source.iterdir() if _is_log(p))
            if not found:
                below = _logs_below(source)
                raise DatasetError(
                    f'{source}: no log files ({", ".join(LOG_SUFFIXES)}, also gzipped) in this '
                    'folder'
                    + (f'; {below} in its subfolders: give those as sources' if below else '')
                )
            _warn_subfolders(source, given)
            files.extend(found)
        elif source.is_file():
            files.append(source)
        else:
            raise DatasetError(f'{source}: no such log file or folder')
    if not files:
        raise DatasetError('no log file given')
    return check_distinct(files, 'import')  # one log twice would be two segments of one motion
