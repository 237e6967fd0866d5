"""Read a log file (CSV or NPZ) into named raw columns, before any conversion.

CSV files are split line by line so that every data row keeps its line number for messages; the
delimiter and the header row are detected unless the mapping names them. Fields quoted by the
csv module's rules (``"time_ms"``, ``"1.5"``) read as their text, whitespace-separated ones too.
A gzip-compressed CSV (``.csv.gz``) is read as its decompressed text. The file's first bytes are
checked against the format it is read as, so that an NPZ read as CSV (or the other way round) is
named as such rather than failing to decode. How a CSV's bytes become text and its text rows
(encodings, a preamble, quoted fields spanning lines) is ``import_text``'s.

Nothing is allocated on a file's word alone: each NPZ array's header (its shape and dtype) is
read from the archive before the array, and an array is refused, naming the file, the array and
its claimed shape, when its header cannot be parsed, when it claims more bytes than the archive
stores of it (a corrupt or crafted header), or when the arrays together would take more than
``MEMORY_SHARE`` of the memory available (a compressed archive can expand to far more than its
size). A gzip-compressed CSV is decompressed up to that share of the memory too, and refused
beyond it. A CSV line may hold up to ``MAX_LINE_CHARS`` characters (a field as many, far beyond
the csv module's default of 128 KiB); a longer line is refused, naming it.

A CSV row with fewer cells than the header (a torn row) is refused as such, whatever the
``nan_policy``; so is one with more non-empty cells. Either message hints at another delimiter
that would split the row into the header's cells, or at a decimal comma; a decimal comma in a
mapped column of a log split by another delimiter is named as one.
"""

from __future__ import annotations

import csv
import gzip
import io
import logging
import math
import re
import zipfile
import zlib
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from id_learning.dataset.import_mapping import ImportMapping
from id_learning.dataset.import_text import (
    MAX_LINE_CHARS,
    decode_text,
    field_limit,
    numbered_rows,
    refuse_preamble,
)
from id_learning.errors import ConfigError, DatasetError
from id_learning.memory import available_memory_bytes

__all__ = ['MAX_LINE_CHARS', 'MEMORY_SHARE', 'LogTable', 'is_float', 'log_suffix', 'read_table']

_LOG = logging.getLogger(__name__)

# Sniffing order: tab and semicolon first, since a comma may be a decimal separator there.
_SNIFF_DELIMITERS = ('tab', ';', ',', 'whitespace')
_SNIFF_LINES = 20
_CSV_SUFFIXES = ('.csv', '.tsv', '.txt', '.dat', '.log')
_ZIP_MAGIC = b'PK\x03\x04'
_GZIP_MAGIC = b'\x1f\x8b'
_NPY_MAGIC = b'\x93NUM'

#: The share of the memory available that one log file's data may take once read: the arrays of
#: an NPZ archive (as their headers claim them), the decompressed text of a gzipped CSV. The
#: import then converts and checks the values, which takes as much again.
MEMORY_SHARE = 0.5
#: The decompressed bytes read at a time from a gzipped CSV.
_GUNZIP_CHUNK = 2**20


@dataclass(frozen=True)
class LogTable:
    """A log's columns as read, before any conversion.

    CSV columns are (N,) arrays of cell strings keyed by header name or 0-based index; NPZ
    columns are the stored arrays keyed by name. ``line_numbers`` holds the 1-based CSV line of
    each data row, or None for NPZ, whose rows are named by their 0-based index.
    """

    source: Path
    columns: dict[str | int, np.ndarray]
    line_numbers: np.ndarray | None

    @property
    def row_label(self) -> Literal['line', 'row']:
        """'line' for CSV line numbers, 'row' for NPZ array indices."""
        return 'row' if self.line_numbers is None else 'line'

    def positions(self, n_rows: int) -> np.ndarray:
        """(N,) position of each data row in the file, as ``row_label`` counts it."""
        return np.arange(n_rows) if self.line_numbers is None else self.line_numbers


def read_table(source: Path, mapping: ImportMapping) -> LogTable:
    """Read the log as the mapping's format says, else as its file suffix says.

    Raises:
        ConfigError: no format is given and the suffix names none, or the file's first bytes
            show another format than the one it is read as (names the format to set).
        DatasetError: the file cannot be read, or holds no data rows.
    """
    file_format = mapping.format or _format_from_suffix(source, mapping)
    said = (
        f"the mapping's format: {file_format}"
        if mapping.format
        else f'its suffix {log_suffix(source)!r}'
    )
    if file_format == 'npz':
        return _read_npz(source, said, mapping.where)
    return _read_csv(source, mapping, _csv_text(source, said, mapping))


def log_suffix(path: Path) -> str:
    """The suffix that names the format, lower case: ``.csv`` also for ``log.csv.gz``."""
    suffixes = [suffix.lower() for suffix in path.suffixes]
    if len(suffixes) > 1 and suffixes[-1] == '.gz':
        return suffixes[-2]
    return path.suffix.lower()


def _format_from_suffix(source: Path, mapping: ImportMapping) -> Literal['csv', 'npz']:
    suffix = log_suffix(source)
    if suffix == '.npz':
        return 'npz'
    if suffix in ('.yaml', '.yml', '.json'):
        raise DatasetError(f'{source}: a YAML/JSON file (a mapping?), not a log (CSV or NPZ)')
    if suffix in _CSV_SUFFIXES:
        return 'csv'
    raise ConfigError(
        f'{mapping.where}: cannot tell the format of {source} from its suffix {suffix!r}; set '
        "format: 'csv' or 'npz'"
    )


def _read_npz(source: Path, said: str, where: str) -> LogTable:
    """The arrays of an NPZ archive; a file without the zip signature is named for what it is."""
    try:
        with source.open('rb') as stream:
            head = stream.read(len(_ZIP_MAGIC))
    except OSError as err:
        raise DatasetError(f'{source}: cannot read NPZ file: {err}') from err
    if not head:
        raise DatasetError(f'{source}: empty file')
    if head.startswith(_GZIP_MAGIC):
        raise DatasetError(
            f'{source}: this file is gzip-compressed; decompress it (gunzip) and import the '
            '.npz (an NPZ archive can be compressed itself: numpy.savez_compressed)'
        )
    if head.startswith(_NPY_MAGIC):
        raise DatasetError(
            f'{source}: a single NPY array, not an NPZ archive of named arrays; save the columns '
            'with numpy.savez(path, name=array, ...)'
        )
    if not head.startswith(_ZIP_MAGIC[:2]):  # PK: any zip record (an empty archive too)
        raise ConfigError(
            f'{source}: {said} does not fit this file, which is no NPZ (zip) archive (it starts '
            f'with {head!r}); for a CSV log set format: csv in {where}'
        )
    try:
        loaded = np.load(source, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile) or loaded.zip is None:
            raise DatasetError(f'{source}: not an NPZ archive of named arrays')
        with loaded:
            _check_npz_headers(source, loaded.zip, _memory_budget())
            columns: dict[str | int, np.ndarray] = {
                key: loaded[key] for key in loaded.files if not key.endswith('/')
            }
    except (OSError, ValueError, TypeError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise DatasetError(f'{source}: cannot read NPZ file: {err}') from err
    except MemoryError:  # the headers were checked; the memory went to another process since
        raise DatasetError(
            f'{source}: cannot read NPZ file: its arrays do not fit in the memory available'
        ) from None
    return LogTable(source, columns, None)


def _check_npz_headers(source: Path, archive: zipfile.ZipFile, budget: int | None) -> None:
    """Refuse an NPZ archive whose arrays cannot be read as their headers claim them.

    Only each array's header is read (a few hundred bytes), never its data: the claimed size is
    checked against what the archive stores of the array and, for all arrays together, against
    ``budget`` [bytes] (None: not known).

    Raises:
        DatasetError: a member name is given twice, a member is no NPY array, or its header
            is unreadable, claims an object array or more data than stored, or the arrays
            exceed ``budget``; names the file, the array and, when read, its claimed shape and
            dtype.
    """
    names = [info.filename for info in archive.infolist()]
    twice = sorted({name.removesuffix('.npy') for name in names if names.count(name) > 1})
    if twice:
        raise DatasetError(
            f'{source}: the archive holds array(s) {twice} more than once (zip members of one '
            'name): which one holds the values is ambiguous; export the log again'
        )
    total = 0
    for info in archive.infolist():
        if info.is_dir():
            continue
        name = info.filename.removesuffix('.npy')
        shape, dtype, claimed, header_bytes = _npy_header(source, archive, info, name)
        what = f'{source}: array {name!r} claims shape {shape} of {dtype} ({_size(claimed)})'
        if dtype.hasobject:
            raise DatasetError(
                f'{source}: array {name!r} holds Python objects (dtype {dtype}), which are not '
                'read (they would be unpickled); save the columns as numbers'
            )
        stored = info.file_size - header_bytes
        if claimed > stored:
            raise DatasetError(
                f'{what}, but the archive stores {_size(max(stored, 0))} of its data: the header '
                'does not fit the data (a corrupt or truncated file); export the log again'
            )
        total += claimed
        if budget is not None and total > budget:
            raise DatasetError(
                f'{what}; with the arrays before it, {_size(total)}: more than '
                f'{MEMORY_SHARE:.0%} of the {_size(int(budget / MEMORY_SHARE))} of memory '
                'available; split the log into shorter files (a folder of logs is imported in '
                'name order)'
            )


def _npy_header(
    source: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, name: str
) -> tuple[tuple[int, ...], np.dtype, int, int]:
    """One NPY member's shape, dtype, claimed data size [bytes] and header size [bytes].

    Raises:
        DatasetError: no NPY magic, an unknown NPY version, or a header numpy cannot parse, or a
            negative dimension; names the file and the array.
    """
    unreadable = f'{source}: array {name!r}: cannot read its NPY header'
    try:
        with archive.open(info) as member:
            magic = member.read(len(np.lib.format.MAGIC_PREFIX))
            if magic != np.lib.format.MAGIC_PREFIX:
                raise DatasetError(
                    f'{source}: {info.filename!r} in the archive is no NPY array (it starts '
                    f'with {magic[:8]!r}); an NPZ holds arrays saved with numpy.savez'
                )
            member.seek(0)
            version = np.lib.format.read_magic(member)
            # Version 3.0 differs from 2.0 only in the header's text encoding (UTF-8 for the
            # field names of a structured dtype); its shape reads the same.
            read_header = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
                if version in ((2, 0), (3, 0))
                else None
            )
            if read_header is None:
                raise DatasetError(f'{unreadable}: unknown NPY format version {version}')
            shape, _, dtype = read_header(member)
            header_bytes = member.tell()
    except DatasetError:
        raise
    except (ValueError, TypeError, SyntaxError, EOFError, OSError, RecursionError) as err:
        raise DatasetError(f'{unreadable}: {err}') from err
    except (zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError) as err:
        raise DatasetError(f'{unreadable}: {err}') from err
    shape = tuple(shape)
    if any(isinstance(n, bool) or n < 0 for n in shape):  # numpy checks for int only
        raise DatasetError(f'{unreadable}: shape {shape} needs whole numbers >= 0')
    return shape, dtype, math.prod(shape) * dtype.itemsize, header_bytes


def _size(n_bytes: int) -> str:
    """A byte count for messages: '745 GiB', '16 kB'... ."""
    for unit, scale in (('GiB', 2**30), ('MiB', 2**20), ('KiB', 2**10)):
        if n_bytes >= scale:
            return f'{n_bytes / scale:.3g} {unit}'
    return f'{n_bytes} bytes'


def _memory_budget() -> int | None:
    """``MEMORY_SHARE`` of the memory available [bytes], or None where it is not known."""
    available = available_memory_bytes()
    return None if available is None else int(MEMORY_SHARE * available)


def _csv_text(source: Path, said: str, mapping: ImportMapping) -> str:
    """The file's text, decompressed when gzip-compressed (``.csv.gz``).

    Raises:
        ConfigError: the file is an NPZ (zip) archive (names the format to set).
        DatasetError: unreadable, a broken gzip stream, or no text in the mapping's encoding.
    """
    budget = _memory_budget()
    try:
        size = source.stat().st_size
        if budget is not None and size > budget:
            raise DatasetError(
                f'{source}: cannot read CSV file: {_size(size)}, more than {MEMORY_SHARE:.0%} of '
                f'the {_size(int(budget / MEMORY_SHARE))} of memory available; split the log '
                'into shorter files (a folder of logs is imported in name order)'
            )
        data: bytes | bytearray = source.read_bytes()
    except OSError as err:
        raise DatasetError(f'{source}: cannot read CSV file: {err}') from err
    if data.startswith(_GZIP_MAGIC):
        data = _gunzip(source, data, budget)
    if data.startswith(_ZIP_MAGIC):
        raise ConfigError(
            f'{source}: {said} does not fit this file, which looks like an NPZ (zip) archive (it '
            f'starts with PK\\x03\\x04); set format: npz in {mapping.where}'
        )
    return decode_text(source, data, mapping)


def _gunzip(source: Path, data: bytes | bytearray, budget: int | None) -> bytearray:
    """A gzip file's content, read in chunks and refused past ``budget`` [bytes] (a gzip bomb).

    Raises:
        DatasetError: a broken gzip stream, or more than ``budget`` bytes once decompressed.
    """
    out = bytearray()
    try:
        with gzip.GzipFile(fileobj=io.BytesIO(data)) as stream:
            while chunk := stream.read(_GUNZIP_CHUNK):
                out += chunk
                if budget is not None and len(out) > budget:
                    raise DatasetError(
                        f'{source}: this gzip file decompresses to more than {_size(budget)} '
                        f'({MEMORY_SHARE:.0%} of the {_size(int(budget / MEMORY_SHARE))} of '
                        'memory available); split the log into shorter files (a folder of logs '
                        'is imported in name order)'
                    )
    except (OSError, EOFError, zlib.error) as err:
        raise DatasetError(f'{source}: cannot decompress this gzip file: {err}') from err
    return out


def _read_csv(source: Path, mapping: ImportMapping, text: str) -> LogTable:
    numbered = numbered_rows(source, text, mapping, None)
    if not numbered:
        raise DatasetError(f'{source}: no data rows')
    refuse_preamble(source, numbered, mapping)
    delimiter = mapping.delimiter or _sniff_delimiter(
        [line for _, line in numbered[:_SNIFF_LINES]],
        source,
        [number for number, _ in numbered[:_SNIFF_LINES]],
    )
    if '"' in text:  # quoted fields may span lines
        numbered = numbered_rows(source, text, mapping, delimiter)
    lines = [line for _, line in numbered]
    rows = _split(lines, delimiter, source, [number for number, _ in numbered])
    has_header = _looks_like_header(rows[0]) if mapping.header == 'auto' else mapping.header
    if has_header is True and mapping.header is True:
        _check_header_row(rows[0], numbered[0][0], mapping, source)
    first_data = 1 if has_header else 0
    names, data_rows = rows[:first_data], rows[first_data:]
    if not data_rows:
        raise DatasetError(f'{source}: no data rows')
    header = names[0] if names else []
    repeated = _repeated_names(header, mapping, source)
    line_numbers = np.array([number for number, _ in numbered[first_data:]])
    shape = _RowShape(source, delimiter, header or data_rows[0], lines[0] if header else '')
    _check_cell_counts(shape, data_rows, lines[first_data:], line_numbers)
    width = max(len(header), *(len(row) for row in data_rows))
    cells = np.array([row + [''] * (width - len(row)) for row in data_rows], dtype=object)
    keys: Sequence[str | int] = header or range(width)
    columns: dict[str | int, np.ndarray] = {
        key: cells[:, j] for j, key in enumerate(keys) if key != '' and key not in repeated
    }
    if delimiter != ',':
        _check_decimal_comma(columns, mapping, line_numbers, source)
    return LogTable(source, columns, line_numbers)


def _split(
    lines: Sequence[str], delimiter: str, source: Path, numbers: Sequence[int]
) -> list[list[str]]:
    """Split lines into stripped fields; one CSV reader per line keeps line numbers exact.

    Fields quoted as the csv module quotes them (``"time_ms"``, ``"1.5"``, a ``""`` inside for
    a quote) read as their text, whatever the delimiter: whitespace too. A line without quotes
    splits as the csv module would split it. A field may hold up to ``MAX_LINE_CHARS``.

    Raises:
        DatasetError: the csv module refuses a line (names the file, the line and why).
    """
    if delimiter == 'whitespace':
        return [_split_whitespace(line) for line in lines]
    char = '\t' if delimiter == 'tab' else delimiter
    return [
        [cell.strip() for cell in line.split(char)]
        if '"' not in line
        else _split_quoted(line, char, source, number)
        for line, number in zip(lines, numbers, strict=True)
    ]


def _split_quoted(line: str, char: str, source: Path, number: int) -> list[str]:
    """One line's stripped fields as the csv module reads them, fields up to MAX_LINE_CHARS."""
    try:
        with field_limit():
            return [
                cell.strip()
                for cell in next(csv.reader([line], delimiter=char, skipinitialspace=True))
            ]
    except csv.Error as err:
        raise DatasetError(f'{source}: line {number}: cannot split it into fields: {err}') from err


#: A field of a whitespace-separated line: quoted (a ``""`` inside for a quote), or bare.
_WHITESPACE_FIELD = re.compile(r'"((?:[^"]|"")*)"(?=\s|$)|(\S+)')


def _split_whitespace(line: str) -> list[str]:
    """A whitespace-separated line's fields; a quoted one may hold spaces (``"q1 deg"``)."""
    if '"' not in line:
        return line.split()
    fields = (match.group(1, 2) for match in _WHITESPACE_FIELD.finditer(line))
    return [
        bare if quoted is None else quoted.replace('""', '"').strip() for quoted, bare in fields
    ]


def _sniff_delimiter(lines: Sequence[str], source: Path, numbers: Sequence[int]) -> str:
    """The first candidate that splits the first line in several fields, as most lines split."""
    for candidate in _SNIFF_DELIMITERS:
        try:
            counts = [len(row) for row in _split(lines, candidate, source, numbers)]
        except DatasetError:  # a quoted line break outside a field of this delimiter's
            continue
        if counts and counts[0] > 1 and 2 * counts.count(counts[0]) > len(counts):
            return candidate
    return ','


def is_float(text: str) -> bool:
    """Whether ``float`` parses the text."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _looks_like_header(row: Sequence[str]) -> bool:
    return any(cell and not is_float(cell) for cell in row)


@dataclass(frozen=True)
class _RowShape:
    """What a CSV row's cells are counted against: the header, or the first data row."""

    source: Path
    delimiter: str
    reference: list[str]
    header_line: str  # '' without a header: the first data row is the reference


def _check_cell_counts(
    shape: _RowShape, rows: Sequence[list[str]], lines: Sequence[str], numbers: np.ndarray
) -> None:
    """Refuse rows with fewer cells, or more non-empty ones, than the header (or first row).

    A short row is torn (cut off, or split by another delimiter); read as empty cells, its
    values would be refused as missing, or dropped unseen by ``nan_policy: drop``. An extra
    cell means a merged or shifted row whose values may sit under the wrong columns. Empty
    cells at the end (a delimiter at the end of some lines) are no data and pass.

    Raises:
        DatasetError: names the file, the first such line, its cell count, how many rows, and a
            delimiter that would split it into the header's cells, or a decimal comma.
    """
    width = len(shape.reference)
    needed = width
    while needed and not shape.reference[needed - 1]:
        needed -= 1
    bad = [
        k
        for k, row in enumerate(rows)
        if len(row) < needed or (len(row) > width and any(row[width:]))
    ]
    if not bad:
        return
    row, line, number = rows[bad[0]], lines[bad[0]], int(numbers[bad[0]])
    more = len(row) > width
    what = 'header' if shape.header_line else 'first data row'
    raise DatasetError(
        f'{shape.source}: line {number} has {len(row)} cells, {abs(len(row) - width)} '
        f'{"more" if more else "fewer"} than the {width} of the {what}; {len(bad)} row(s) are '
        f'affected. Fix the log ({"a merged or shifted row" if more else "a torn row"}?)'
        + _delimiter_hint(shape, line, number)
    )


def _delimiter_hint(shape: _RowShape, line: str, number: int) -> str:
    """A hint at another delimiter that splits the line as it should be split, or ''."""
    width = len(shape.reference)
    used = {'tab': 'tab', 'whitespace': 'whitespace'}.get(shape.delimiter, repr(shape.delimiter))
    decimal = ' (a decimal comma?)' if shape.delimiter == ',' and re.search(r'\d,\d', line) else ''
    for other in (d for d in _SNIFF_DELIMITERS if d != shape.delimiter):
        named = other if other in ('tab', 'whitespace') else repr(other)
        try:
            cells = len(_split([line], other, shape.source, [number])[0])
            header = len(_split([shape.header_line], other, shape.source, [number])[0])
        except DatasetError:  # a quoted line break outside a field of this delimiter's
            continue
        if shape.header_line and header == cells > 1:
            return (
                f'; the header and line {number} split by {named} into {cells} cells: set '
                f'delimiter: {named}{decimal}'
            )
        if cells == width > 1:
            what = (
                f'the header is split by {used}'
                if shape.header_line
                else f'the first data row by {used}'
            )
            return f'; {what} but line {number} by {named}?{decimal}'
    return f'; {decimal[2:-1]}' if decimal else ''


#: A number written with a decimal comma: ``0,5``, ``-37,25``.
_DECIMAL_COMMA = re.compile(r'[+-]?\d+,\d+(?:[eE][+-]?\d+)?')


def _check_decimal_comma(
    columns: dict[str | int, np.ndarray], mapping: ImportMapping, numbers: np.ndarray, source: Path
) -> None:
    """Refuse a mapped column written with decimal commas (``37,5``), which reads as no number.

    Raises:
        DatasetError: names the file, the first such line, the column and the cell.
    """
    for key in sorted(mapping.mapped_columns() & columns.keys(), key=str):
        for k, cell in enumerate(columns[key].tolist()):
            if _DECIMAL_COMMA.fullmatch(str(cell)):
                raise DatasetError(
                    f'{source}: line {int(numbers[k])}, column {key!r}: {cell!r} is not a '
                    'number: a decimal comma? Write the log with decimal points '
                    f'({str(cell).replace(",", ".")!r})'
                )


def _check_header_row(row: list[str], line: int, mapping: ImportMapping, source: Path) -> None:
    """Refuse ``header: true`` over a file whose first row holds numbers only: no header.

    A header of numbers alone can name columns only when it holds every name the mapping uses.

    Raises:
        DatasetError: names the file, the line, its first cells and the settings that fit.
    """
    if _looks_like_header(row):
        return
    names = _mapped_names(mapping)
    if names and names <= set(row):
        return
    shown = ', '.join(row[:3]) + (', ...' if len(row) > 3 else '')
    raise DatasetError(
        f'{source}: the mapping says header: true, but line {line}, the first row, holds only '
        f'numbers ({shown}): the file has no header row; set header: false (map columns by '
        '0-based index) or header: auto'
    )


def _mapped_names(mapping: ImportMapping) -> set[str]:
    """The column names the mapping reads (time and every joint's quantities)."""
    return {key for key in mapping.mapped_columns() if isinstance(key, str)}


def _repeated_names(names: list[str], mapping: ImportMapping, source: Path) -> set[str]:
    """The header's names given more than once, none of which the mapping reads.

    A mapped name given twice is ambiguous: which column holds the values? An unmapped one
    (two ``notes`` columns) is read by nobody, so it is said and left out.

    Raises:
        DatasetError: a mapped column name is given more than once (names it and the columns).
    """
    counts = Counter(names)
    repeated = {name for name in names if name and counts[name] > 1}
    mapped = sorted(repeated & _mapped_names(mapping))
    if mapped:
        where = {name: [k for k, given in enumerate(names) if given == name] for name in mapped}
        raise DatasetError(
            f'{source}: the header names the mapped column(s) {mapped} more than once (at '
            f'0-based positions {where}): which one holds the values is ambiguous; rename or '
            'remove the others'
        )
    if repeated:
        _LOG.warning('%s: the header names columns %s more than once; the mapping reads none of '
                     'them, so they are left out', source, sorted(repeated))  # fmt: skip
    return repeated
