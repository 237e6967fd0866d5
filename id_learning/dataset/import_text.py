"""A CSV log's text: decoded, split into rows that keep their line numbers, its preamble named.

A row is one line, unless a quoted field spans lines (RFC 4180: a note with a line break): such a
row is read whole and named by its first line; a quote never closed is refused at the line that
opens it, and so is a row longer than ``MAX_LINE_CHARS``, so one stray quote cannot swallow the
file. Text that does not decode is refused naming its line and byte and the ``encoding`` to set;
a trace's preamble (lines before the header) is named with the ``skip_lines`` that skips it.
"""

from __future__ import annotations

import codecs
import contextlib
import csv
from collections.abc import Iterator, Sequence
from pathlib import Path

from id_learning.dataset.import_mapping import ImportMapping
from id_learning.errors import DatasetError

__all__ = ['MAX_LINE_CHARS', 'bom_encoding', 'decode_text', 'numbered_rows', 'refuse_preamble']

#: The characters a CSV line may hold (16 Mi): a long unmapped field (a note, a dump) is read; a
#: longer line, most likely no line of a log (a file without line breaks), is refused.
MAX_LINE_CHARS = 2**24
#: The bytes looked at for NUL characters: UTF-16 without its byte order mark, or no text.
_NUL_WINDOW = 4096
#: The rows searched for the mapped column names when the first row does not hold them.
_PREAMBLE_ROWS = 50
_CANDIDATES = {'tab': '\t', ';': ';', ',': ',', 'whitespace': ' '}


def decode_text(source: Path, data: bytes | bytearray, mapping: ImportMapping) -> str:
    """The log's text in the mapping's encoding (UTF-8 by default, UTF-16/32 by their BOM).

    Raises:
        DatasetError: a byte sequence that is not text in that encoding (names the line, the
            byte and the encoding to set), or NUL characters in a file read as UTF-8.
    """
    encoding = codecs.lookup(mapping.encoding).name
    if encoding == 'utf-8':
        if (marked := bom_encoding(data)) is not None:
            encoding = marked
        elif b'\x00' in data[:_NUL_WINDOW]:
            line = data.count(b'\n', 0, data.index(b'\x00')) + 1
            raise DatasetError(
                f'{source}: line {line} holds NUL characters, which no UTF-8 log has: UTF-16 '
                f"without a byte order mark? Set encoding: 'utf-16-le' (or 'utf-16-be') in "
                f'{mapping.where}; or this is no text file'
            )
        else:
            encoding = 'utf-8-sig'
    try:
        return bytes(data).decode(encoding)
    except UnicodeDecodeError as err:
        line = data.count(b'\n', 0, err.start) + 1
        line_start = data.rfind(b'\n', 0, err.start) + 1
        line_end = data.find(b'\n', err.start)
        text = bytes(data[line_start : line_end if line_end >= 0 else len(data)])
        shown = text[:120].decode(encoding, errors='replace').strip()
        hint = (
            f"set encoding: 'cp1252' (a Windows export) or 'latin-1' in {mapping.where}"
            if encoding == 'utf-8-sig'
            else f'is the file in another encoding than {mapping.encoding!r}? Set encoding: in '
            f'{mapping.where}'
        )
        raise DatasetError(
            f'{source}: line {line}, byte '
            f'{err.start - line_start + 1}: {bytes(data[err.start : err.end])!r} is not '
            f'{mapping.encoding} text ({shown!r}); {hint}'
        ) from err


def bom_encoding(data: bytes | bytearray) -> str | None:
    """'utf-32' or 'utf-16' when ``data`` starts with that byte order mark, else None."""
    if data.startswith((codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE)):  # before UTF-16's FF FE
        return 'utf-32'
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return 'utf-16'
    return None


def numbered_rows(
    source: Path, text: str, mapping: ImportMapping, delimiter: str | None
) -> list[tuple[int, str]]:
    """The file's rows, each with the 1-based line it starts on, from line ``skip_lines + 1``.

    Blank and comment lines are left out. With a ``delimiter``, a row whose quoted field spans
    lines is one row, its lines joined by a line feed; without one, every line is a row (enough
    to sniff the delimiter).

    Raises:
        DatasetError: a quoted field never closed, or a row longer than ``MAX_LINE_CHARS``.
    """
    lines = text.splitlines()
    rows: list[tuple[int, str]] = []
    k = mapping.skip_lines
    char = None if delimiter is None else _CANDIDATES.get(delimiter, delimiter)
    while k < len(lines):
        line = lines[k]
        if char is not None and '"' in line and _opens_field(line, char):
            span = _quoted_span(source, lines, k, char)
            rows.append((k + 1, '\n'.join(lines[k : k + span])))
            k += span
            continue
        if line.strip() and not (mapping.comment and line.lstrip().startswith(mapping.comment)):
            rows.append((k + 1, line))
        k += 1
    too_long = [(number, len(line)) for number, line in rows if len(line) > MAX_LINE_CHARS]
    if too_long:
        raise DatasetError(
            f'{source}: line {too_long[0][0]} has {too_long[0][1]:,} characters, more than the '
            f'{MAX_LINE_CHARS:,} a log line may have ({len(too_long)} such line(s)); is this a '
            'log of one row per line? Split the long lines, or drop the long column'
        )
    return rows


@contextlib.contextmanager
def field_limit() -> Iterator[None]:
    """Let the csv module read fields up to ``MAX_LINE_CHARS`` (its default is 128 KiB)."""
    limit = csv.field_size_limit()
    csv.field_size_limit(max(limit, MAX_LINE_CHARS))
    try:
        yield
    finally:
        csv.field_size_limit(limit)


def _opens_field(line: str, char: str) -> bool:
    """Whether the line ends inside a quoted field (by the csv module's reading of quotes)."""
    try:
        with field_limit():
            next(csv.reader([line], delimiter=char, skipinitialspace=True, strict=True))
    except csv.Error as err:
        return 'unexpected end of data' in str(err)
    return False


def _quoted_span(source: Path, lines: Sequence[str], first: int, char: str) -> int:
    """How many lines the row starting at ``lines[first]`` spans (it opens a quoted field).

    Raises:
        DatasetError: the quote is not closed by the end of the file or within MAX_LINE_CHARS.
    """
    reader = csv.reader(
        (line + '\n' for line in lines[first:]), delimiter=char, skipinitialspace=True, strict=True
    )
    try:
        with field_limit():
            next(reader)
    except csv.Error as err:
        how = (
            'before the end of the file'
            if 'unexpected end of data' in str(err)
            else f'within {MAX_LINE_CHARS:,} characters'
        )
        raise DatasetError(
            f'{source}: line {first + 1}: a quoted field opens here and is not closed {how}; '
            f'close its quote ({lines[first][:80]!r})'
        ) from err
    return reader.line_num


def refuse_preamble(source: Path, rows: Sequence[tuple[int, str]], mapping: ImportMapping) -> None:
    """Refuse a log whose mapped column names are on a later row than the first: a preamble.

    Raises:
        DatasetError: names the header's line, the first row, and the ``skip_lines`` to set.
    """
    names = {column for column in mapping.mapped_columns() if isinstance(column, str)}
    if not names or mapping.header is False or not rows or _holds(rows[0][1], names):
        return
    for number, line in rows[1:_PREAMBLE_ROWS]:
        if _holds(line, names):
            raise DatasetError(
                f'{source}: the mapped columns are named on line {number}, not on line '
                f'{rows[0][0]}, the first row ({rows[0][1][:60]!r}): a preamble before the '
                f'header? Set skip_lines: {number - 1} in {mapping.where} (or comment: with '
                "the preamble's prefix)"
            )


def _holds(line: str, names: set[str]) -> bool:
    """Whether some delimiter splits the line into fields that include every name."""
    for char in _CANDIDATES.values():
        try:
            with field_limit():
                fields = next(csv.reader([line], delimiter=char, skipinitialspace=True))
        except csv.Error:
            continue
        if names <= {field.strip() for field in fields}:
            return True
    return False
