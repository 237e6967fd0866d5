"""The log files an import reads: files as given, folders as the log files in them.

A folder is read without its subfolders: a subfolder may hold a log of its own, a backup or an
export, and which of them belong to this recording only the user knows. Nothing that looks like a
log is left out without a word, though: subfolders holding log files are named in a warning with
the way to import them (name them as sources too).

A folder's file is a log when its suffix is a log's and its head reads as one (``log_problem``):
a table whose rows split alike into cells that are mostly numbers. Notes beside the logs (a
README.txt, a notes.log, a program's text log) are no table: they are named in one warning and
skipped, and a folder where nothing reads as a log is refused, naming its files and why. A file
given as a source is read whatever it holds (the reader names what is wrong with it). Files with
other suffixes (a mapping, a README.md, a plot) are no logs and are passed over. An entry named
like a log that is no regular file (a FIFO, a device, a socket, a link to nothing) is refused,
naming it and what it is, never opened: passed over, a log meant to be there would be lost.
A mapping (or other YAML/JSON file) given as a source is refused as such, not read as a table.
"""

from __future__ import annotations

import gzip
import logging
import re
import zlib
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from id_learning.bag.distinct import check_distinct
from id_learning.config_io import broken_link, special_kind
from id_learning.dataset.import_readers import is_float, log_suffix
from id_learning.dataset.import_text import bom_encoding
from id_learning.errors import DatasetError

__all__ = ['LOG_SUFFIXES', 'log_files', 'log_problem', 'mapping_problem']

logger = logging.getLogger(__name__)

#: The suffixes of files a folder contributes (also gzipped: ``.csv.gz``).
LOG_SUFFIXES = ('.csv', '.tsv', '.txt', '.dat', '.log', '.npz')
_NAMED = 5  # subfolders (or files) named in a warning, then a count
#: How much of a text file ``log_problem`` reads and judges [bytes]: hundreds of lines.
_HEAD_BYTES = 1 << 16
#: Suffixes of a mapping or settings file, no log.
_MAPPING_SUFFIXES = ('.yaml', '.yml', '.json')
#: A YAML mapping's key (``time:``); a line of YAML: a key, a list item, a comment.
_YAML_KEY = re.compile(r'[A-Za-z_][\w .-]*:(?:\s|$)')
_YAML_LINE = re.compile(r'\s*(?:-\s|-$|#|[A-Za-z_][\w .-]*:(?:\s|$))')
#: Field separators a log's rows split by (None: whitespace), as the reader sniffs them.
_SEPARATORS = ('\t', ';', ',', None)


def _is_log(path: Path) -> bool:
    return path.is_file() and log_suffix(path) in LOG_SUFFIXES and log_problem(path) is None


def _is_number(cell: str, separator: str | None) -> bool:
    # A decimal comma (1,5) where the comma separates no fields, as the importer reads it.
    return is_float(cell) or (separator != ',' and is_float(cell.replace(',', '.')))


def _unquoted(cell: str) -> str:
    """A cell's text without the quotes CSV may put around it (``"1.5"``, ``"time_ms"``)."""
    cell = cell.strip()
    return cell[1:-1].strip() if len(cell) > 1 and cell[0] == cell[-1] == '"' else cell


def log_problem(path: Path) -> str | None:
    """Why a text file is no log, in words; None when its head reads as one (or it is an NPZ).

    A log is a table: in its first ``_HEAD_BYTES``, at least two rows split alike (by tab, ';',
    ',' or whitespace) into cells of which two or more, and at least half, are numbers (quotes
    around a cell, as CSV writes them, are no part of it). Header, comment and blank lines are
    passed over. Prose has no such rows, nor has a binary file. A zip archive (an NPZ, whatever
    its name) is left to the reader, as the mapping's format says.
    """
    if log_suffix(path) == '.npz':
        return None
    try:
        with path.open('rb') as stream:
            head = stream.read(_HEAD_BYTES)
        if head.startswith(b'\x1f\x8b'):
            with gzip.open(path) as stream:
                head = stream.read(_HEAD_BYTES)
    except (OSError, EOFError, zlib.error):
        return None  # the reader names why it cannot be read: never skipped for it
    if head.startswith(b'PK'):
        return None  # an NPZ named otherwise: the reader says what it is, or reads it
    encoding = _text_encoding(head)
    if encoding is None:
        return 'binary, no text'
    lines = head.decode(encoding, errors='replace').splitlines()
    if len(head) == _HEAD_BYTES:
        lines = lines[:-1]  # cut off by the read
    lines = [line for line in lines if line.strip()]
    if not lines:
        return 'empty'
    for separator in _SEPARATORS:
        widths = Counter(
            len(cells)
            for cells in (
                [cell for cell in (_unquoted(c) for c in line.split(separator)) if cell]
                for line in lines
            )
            if 2 * sum(_is_number(cell, separator) for cell in cells) >= max(len(cells), 4)
        )
        if widths and widths.most_common(1)[0][1] >= 2:
            return None
    where = f'first {len(lines)} lines' if len(lines) > 1 else 'one line'
    return f'no table of numbers in its {where}'


def _text_encoding(head: bytes) -> str | None:
    """The encoding a file's head is judged in; None for bytes that are no text.

    UTF-16 by its byte order mark, or by a NUL in (nearly) every other byte (text in UTF-16
    without a mark, which the reader then names); else UTF-8.
    """
    if (marked := bom_encoding(head)) is not None:
        return marked
    if b'\0' not in head:
        return 'utf-8-sig'
    even, odd = head[0::2], head[1::2]
    if 0 not in even and odd.count(0) >= 0.9 * len(odd):
        return 'utf-16-le'
    if 0 not in odd and even.count(0) >= 0.9 * len(even):
        return 'utf-16-be'
    return None


def mapping_problem(path: Path) -> str | None:
    """Why a file given as a log looks like a mapping or other YAML/JSON file; None if not.

    Its suffix is ``.yaml``, ``.yml`` or ``.json``; or its first line opens a JSON object; or its
    first line is a YAML ``key: value`` and most of its first 20 lines are YAML.
    """
    suffix = log_suffix(path)
    if suffix in _MAPPING_SUFFIXES:
        return f'its suffix is {suffix!r}'
    try:
        with path.open('rb') as stream:
            head = stream.read(4096).decode('utf-8-sig', errors='replace')
    except OSError:
        return None  # the reader names why it cannot be read
    lines = [line for line in head.splitlines()[:20] if line.strip()]
    first = lines[0].strip() if lines else ''
    if first.startswith('{'):
        return 'its first line opens a JSON object'
    if _YAML_KEY.match(first) and 2 * sum(bool(_YAML_LINE.match(s)) for s in lines) > len(lines):
        return f'its first line reads {first[:40]!r}, a YAML key: value'
    return None


def _skip_notes(folder: Path, files: Sequence[Path]) -> list[Path]:
    """The files of ``folder`` that read as logs; the others are named in one warning.

    Raises:
        DatasetError: none reads as a log (names each file and why).
    """
    problems = {path: log_problem(path) for path in files}
    logs = [path for path, problem in problems.items() if problem is None]
    notes = [f'{path.name} ({problem})' for path, problem in problems.items() if problem]
    if not logs:
        raise DatasetError(
            f'{folder}: no file in this folder reads as a log: {"; ".join(notes)}; give the log '
            'files themselves as sources to have them read as logs'
        )
    if notes:
        named = '; '.join(notes[:_NAMED]) + (
            f'; ... ({len(notes)} in all)' * (len(notes) > _NAMED)
        )
        logger.warning(
            '%s: skipped %d file%s that read as no log: %s; give a file as a source itself to '
            'have it read as a log',
            folder,
            len(notes),
            's' if len(notes) > 1 else '',
            named,
        )
    return logs


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


def _refuse_no_files(named: Sequence[Path]) -> None:
    """Refuse a folder's entry named like a log that is no regular file (a folder passes).

    A FIFO, a device, a socket or a link to nothing named ``b.csv`` may stand for a log that
    was to be recorded there: passed over, that log would be left out of the bag without a
    word. Each is looked at with ``stat`` only, never opened (a FIFO would wait for a writer).

    Raises:
        DatasetError: names the entry and what it is.
    """
    for path in named:
        link = broken_link(path)
        if link is not None:
            raise DatasetError(
                f'{path}: {link}; it is named like a log of this folder: restore its target, or '
                'remove the link'
            )
        kind = special_kind(path)
        if kind is None or kind == 'a folder':  # a subfolder is named by _warn_subfolders
            continue
        hint = (
            'an import reads a log more than once: write it to a file in its place'
            if kind.startswith('a FIFO')
            else 'move it out of the folder, or give the log files themselves as sources'
        )
        raise DatasetError(
            f"{path}: {kind}, not a log file, yet named like one of this folder's logs (a log "
            f'there would be left out of the bag); {hint}'
        )


def log_files(sources: Sequence[Path | str]) -> list[Path]:
    """The log files named: files as given, folders as their log files in name order.

    A folder's files that read as no log (``log_problem``: notes beside the logs) are named in
    a warning and skipped. A folder's subfolders are not read; those holding log files are
    named in a warning, unless they are (or hold) sources themselves.

    Raises:
        DatasetError: a source does not exist or is no file or folder (a device, a FIFO: named),
            a folder holds an entry named like a log that is no file (a FIFO, a device, a
            socket, a link to nothing: named, never opened), or a folder holds no log file (it
            names the subfolders that do, or its files that read as no log).
        ConfigError: one log given twice (same file, or identical bytes), naming it.
    """
    files: list[Path] = []
    given = [Path(source).resolve() for source in sources]
    for source in map(Path, sources):
        if source.is_dir():
            named = sorted(p for p in source.iterdir() if log_suffix(p) in LOG_SUFFIXES)
            _refuse_no_files(named)
            found = [p for p in named if p.is_file()]
            if not found:
                below = _logs_below(source)
                raise DatasetError(
                    f'{source}: no log files ({", ".join(LOG_SUFFIXES)}, also gzipped) in this '
                    'folder'
                    + (f'; {below} in its subfolders: give those as sources' if below else '')
                )
            found = _skip_notes(source, found)
            _warn_subfolders(source, given)
            files.extend(found)
        elif source.is_file():
            if (why := mapping_problem(source)) is not None:
                raise DatasetError(
                    f'{source}: this looks like a mapping or other YAML/JSON file ({why}), not '
                    'a log; give the mapping with --mapping and the log files (CSV or NPZ) as '
                    'sources'
                )
            files.append(source)
        elif (kind := special_kind(source)) is not None:
            # A device may never end; a pipe cannot be read twice (its head judged, then read).
            hint = (
                'an import reads a log more than once: write it to a file and import that'
                if kind.startswith('a FIFO')
                else 'give a log file or a folder of them'
            )
            raise DatasetError(f'{source}: {kind}, not a log file or folder; {hint}')
        else:
            raise DatasetError(f'{source}: no such log file or folder')
    if not files:
        raise DatasetError('no log file given')
    return check_distinct(files, 'import')  # one log twice would be two segments of one motion
