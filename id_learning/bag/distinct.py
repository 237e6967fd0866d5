"""Inputs given twice: the same file or bag, a copy of its bytes, or its messages restored.

Training, evaluation or an import that reads one recording twice weighs it double.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from pathlib import Path

from id_learning.bag.reader import bag_info, data_files, iter_raw
from id_learning.errors import BagError, ConfigError

__all__ = ['check_distinct']


def _content_key(path: Path) -> tuple[int, tuple[str, ...]]:
    """Total size and the sorted SHA-256 digests of a file, or of a bag folder's storage files.

    File names are left out, so a renamed storage file still matches its original.
    """
    digests: list[str] = []
    size = 0
    for file in data_files(path):
        digest = hashlib.sha256()
        with file.open('rb') as stream:
            for block in iter(lambda: stream.read(1 << 20), b''):
                digest.update(block)
                size += len(block)
        digests.append(digest.hexdigest())
    return size, tuple(sorted(digests))


def check_distinct(paths: Sequence[Path | str], what: str) -> list[Path]:
    """``paths`` as Paths, refused when one file or bag is given twice.

    Twice means the same resolved path, or the same storage bytes under another name (a copy,
    even with an edited metadata.yaml), or a bag holding the same messages in other storage
    bytes (re-compressed, re-chunked): either would weigh one recording double in training,
    evaluation or an import. Files are hashed only for inputs of equal storage size and
    messages only for bags whose metadata states the same span and counts, so distinct inputs
    cost a ``stat`` and a metadata read each.

    Raises:
        ConfigError: names both spellings of the input given twice and ``what`` (e.g. --bag).
    """
    out = [Path(p) for p in paths]
    seen: dict[Path, Path] = {}
    for path in out:
        key = path.resolve()
        if key in seen:
            raise ConfigError(
                f'{what}: {path} is given twice ({seen[key]} and {path}); give it once'
            )
        seen[key] = path
    by_size: dict[int, list[Path]] = {}
    for path in out:
        if path.exists() and data_files(path):
            by_size.setdefault(sum(f.stat().st_size for f in data_files(path)), []).append(path)
    for group in (g for g in by_size.values() if len(g) > 1):
        _refuse_equal(group, _content_key, what, 'identical content')
    by_span: dict[tuple[object, ...], list[Path]] = {}
    for path in out:
        if path.is_dir() and (path / 'metadata.yaml').is_file():
            by_span.setdefault(_span_key(path), []).append(path)
    for group in (g for k, g in by_span.items() if k and len(g) > 1):
        _refuse_equal(group, _message_key, what, 'the same messages, stored differently')
    return out


def _refuse_equal(
    group: Sequence[Path], key: Callable[[Path], object], what: str, how: str
) -> None:
    """Refuse the first path of ``group`` whose ``key`` an earlier one shares."""
    seen: dict[object, Path] = {}
    for path in group:
        value = key(path)
        if value in seen:
            raise ConfigError(
                f'{what}: {path} holds the same data as {seen[value]} ({how}); '
                'give each recording once'
            )
        seen[value] = path


def _span_key(path: Path) -> tuple[object, ...]:
    """Start, duration and per-topic counts a bag's metadata states; () when it does not open.

    Bags that agree on all of it are hashed message by message: a copy re-compressed or
    converted to another storage has other bytes but the same messages.
    """
    try:
        info = bag_info(path)
    except BagError:
        return ()  # the command's own reading names what is wrong with it
    counts = tuple(sorted((t.name, t.count) for t in info.topics))
    return (info.start_ns, info.duration_ns, counts)


def _message_key(path: Path) -> str:
    """SHA-256 over every message's topic, log time and serialized bytes, in log order."""
    digest = hashlib.sha256()
    topics = [t.name for t in bag_info(path).topics]
    for topic, log_ns, data in iter_raw(path, topics):
        digest.update(f'{topic}\0{log_ns}\0{len(data)}\0'.encode())
        digest.update(data)
    return digest.hexdigest()
