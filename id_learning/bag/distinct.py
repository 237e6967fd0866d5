"""Inputs given twice: the same file or bag, its bytes, its messages, or samples cut from it.

Training, evaluation or an import that reads one recording twice weighs it double; samples that
two recordings (or two segments of one bag) share put the same motion into the training and the
test part.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from id_learning.bag.reader import bag_info, data_files, iter_raw
from id_learning.errors import BagError, ConfigError, DatasetError

__all__ = [
    'MIN_SHARED_SAMPLES',
    'Samples',
    'check_distinct',
    'refuse_shared_samples',
    'repeated_samples',
    'shared_samples',
    'shared_stamps',
]


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


#: A recording's samples, to tell whether two recordings hold the same ones: (name, stamps [ns],
#: positions (N, n) [rad] in one joint order[, noisy (N, m) or None]). The name says where it is
#: (a bag, a segment). ``noisy``: values each recording measures with its own sensor noise
#: (motor currents, measured velocities), equal in two recordings only when one is a copy.
Samples = (
    tuple[str, np.ndarray, np.ndarray] | tuple[str, np.ndarray, np.ndarray, np.ndarray | None]
)

#: Two recordings that share this many moving samples hold the same motion. Fewer happen by
#: chance: twin recordings leave one rest pose at one stamp by the same encoder count.
MIN_SHARED_SAMPLES = 100


def _row_keys(q: np.ndarray) -> np.ndarray:
    """(N,) one comparable key per row of ``q``: its float64 bytes (-0.0 as 0.0)."""
    rows = np.ascontiguousarray(q, dtype=np.float64) + 0.0
    return rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1]))).ravel()


def _compared(first: Samples, second: Samples) -> tuple[np.ndarray, np.ndarray]:
    """The rows compared: the positions, then the noisy values where both recordings have them.

    Positions alone cannot tell a copy from a second run of one commanded motion (a twin's
    positions are the trajectory's, quantised, in every run); the noisy values can.
    """
    a_q, b_q = first[2], second[2]
    a_noisy = first[3] if len(first) == 4 else None
    b_noisy = second[3] if len(second) == 4 else None
    if a_noisy is None or b_noisy is None or a_noisy.shape[1] != b_noisy.shape[1]:
        return a_q, b_q
    return np.hstack([a_q, a_noisy]), np.hstack([b_q, b_noisy])


def shared_samples(first: Samples, second: Samples) -> tuple[np.ndarray, np.ndarray]:
    """The stamps [ns] in ``first`` and in ``second`` of the moving samples both hold.

    A sample is held by both when all its values are equal: positions, and the noisy values
    (currents, measured velocities) where both recordings give them. Only a copy holds
    another recording's samples: a second run of the same commanded motion repeats the
    positions (a twin's exactly) but not the sensors' noise. A copy may keep the stamps (a bag
    cut from another) or shift them by a constant (a re-stamped copy; an import of overlapping
    logs, whose files follow each other in the bag): the pairs at the most common stamp shift
    are returned, in time order. Moving samples are those whose positions differ from the
    sample before in ``first``. Without noisy values on both sides, positions alone decide,
    and two runs of one noise-free trajectory look like copies.
    """
    _, a_ns, a_q = first[:3]
    b_ns = second[1]
    empty = np.empty(0, dtype=np.int64)
    if len(a_ns) < 2 or not len(b_ns):
        return empty, empty
    a_rows, b_rows = _compared(first, second)
    moving = np.flatnonzero(np.any(a_q[1:] != a_q[:-1], axis=1)) + 1
    _, in_a, in_b = np.intersect1d(
        _row_keys(a_rows)[moving], _row_keys(b_rows), assume_unique=False, return_indices=True
    )
    if not in_a.size:
        return empty, empty
    a_at, b_at = np.asarray(a_ns)[moving[in_a]], np.asarray(b_ns)[in_b]
    shifts, counts = np.unique(b_at - a_at, return_counts=True)
    same = b_at - a_at == shifts[np.argmax(counts)]
    order = np.argsort(a_at[same])
    return a_at[same][order], b_at[same][order]


def repeated_samples(samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """The stamps [ns] of moving samples a recording holds twice: (first copy, second copy).

    ``shared_samples`` within one recording: a looped replay recorded into one bag, or a log
    appended to itself, repeats every value of a stretch (positions and the sensors' noise) at
    later stamps. The pairs at the most common stamp shift are returned, in time order.
    """
    _, ns, q = samples[:3]
    empty = np.empty(0, dtype=np.int64)
    if len(ns) < 3:
        return empty, empty
    noisy = samples[3] if len(samples) == 4 else None
    rows = q if noisy is None else np.hstack([q, noisy])
    moving = np.flatnonzero(np.any(q[1:] != q[:-1], axis=1)) + 1
    keys = _row_keys(rows)[moving]
    order = np.argsort(keys, kind='stable')  # equal rows stay in time order
    same = keys[order][1:] == keys[order][:-1]
    if not same.any():
        return empty, empty
    at = np.asarray(ns)[moving]
    earlier, later = at[order[:-1][same]], at[order[1:][same]]
    shifts, counts = np.unique(later - earlier, return_counts=True)
    keep = later - earlier == shifts[np.argmax(counts)]
    index = np.argsort(earlier[keep])
    return earlier[keep][index], later[keep][index]


def shared_stamps(first: Samples, second: Samples) -> np.ndarray:
    """The stamps [ns] in ``first`` of the moving samples ``second`` holds too."""
    return shared_samples(first, second)[0]


def refuse_shared_samples(recordings: Sequence[Samples], why: str) -> None:
    """Refuse two recordings that hold the same motion, naming both and the shared span.

    Raises:
        DatasetError: the first pair that shares ``MIN_SHARED_SAMPLES`` moving samples or more.
    """
    for i, first in enumerate(recordings):
        for second in recordings[i + 1 :]:
            in_first, in_second = shared_samples(first, second)
            if in_first.size < MIN_SHARED_SAMPLES:
                continue
            span_s = (int(in_first[-1]) - int(in_first[0])) * 1e-9
            where = f'stamps {int(in_first[0])} to {int(in_first[-1])} ns'
            if in_second[0] != in_first[0]:
                where += (
                    f' in the first, {int(in_second[0])} to {int(in_second[-1])} ns in the second'
                )
            raise DatasetError(
                f'{first[0]} and {second[0]} hold the same {in_first.size} samples ({where}, '
                f'{span_s:.1f} s): {why}'
            )
