"""Thread counts of torch and numpy's BLAS for one-sample inference.

One sample per call gains nothing from more threads, and on a loaded machine the extra threads
wait for each other; more threads than the CPU cores the process may run on
(``oversubscription``) wait for each other even on an idle one.
"""

from __future__ import annotations

import ctypes
import logging
import os
from collections.abc import Collection, Iterable

import torch

__all__ = [
    'configure_inference_threads',
    'cpu_cores',
    'mapped_libraries',
    'oversubscription',
    'set_openblas_threads',
]

_LOG = logging.getLogger(__name__)


def configure_inference_threads(threads: int) -> None:
    """Fix torch's and numpy's BLAS thread counts (one sample per call gains nothing from more).

    numpy's OpenBLAS otherwise starts a thread per core for larger products; on a loaded 2-core
    machine those threads wait for each other (LSTM windows in numpy: p99 72 ms per step with
    the default, 4.8 ms with one thread).

    Raises:
        ValueError: threads < 1.
    """
    if threads < 1:
        raise ValueError(f'threads must be >= 1, got {threads}')
    torch.set_num_threads(threads)
    # The inter-op pool can be sized once per process only, before any parallel work.
    try:
        torch.set_num_interop_threads(threads)
    except RuntimeError:
        _LOG.debug('inter-op thread count already fixed; left as it is')
    if not set_openblas_threads(threads):
        _LOG.debug('no OpenBLAS loaded with a known thread setter; numpy threads left as they are')


#: OpenBLAS's thread setter under the names of its builds (plain, 64-bit index, numpy's wheels).
_OPENBLAS_SETTERS = (
    'openblas_set_num_threads',
    'openblas_set_num_threads64_',
    'scipy_openblas_set_num_threads',
    'scipy_openblas_set_num_threads64_',
)


def set_openblas_threads(threads: int) -> bool:
    """Set the thread count of every OpenBLAS loaded in this process (numpy's BLAS).

    Returns:
        Whether a setter was found and called.
    """
    try:
        with open('/proc/self/maps', encoding='utf-8', errors='surrogateescape') as maps:
            paths = mapped_libraries(maps, 'openblas')
    except OSError:
        return False
    found = False
    for path in sorted(paths):
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _OPENBLAS_SETTERS:
            setter = getattr(library, name, None)
            if setter is not None:
                setter(ctypes.c_int(threads))
                found = True
                break
    return found


def mapped_libraries(maps: Iterable[str], name: str) -> set[str]:
    """The files of /proc/<pid>/maps lines whose path holds ``name`` (any case).

    A line is address, perms, offset, device, inode and the path, which may hold spaces (a
    venv under a folder with a space in its name).
    """
    paths = set()
    for line in maps:
        fields = line.rstrip('\n').split(maxsplit=5)
        if len(fields) == 6 and name in fields[5].lower():
            paths.add(fields[5])
    return paths


def cpu_cores() -> set[int]:
    """The CPU cores this process may run on (its affinity; all of them where it has none)."""
    try:
        return set(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return set(range(os.cpu_count() or 1))


def _ranges(cores: Collection[int]) -> str:
    """'0-3, 6' for the cores {0, 1, 2, 3, 6}."""
    spans: list[list[int]] = []
    for core in sorted(cores):
        if spans and core == spans[-1][1] + 1:
            spans[-1][1] = core
        else:
            spans.append([core, core])
    return ', '.join(f'{a}' if a == b else f'{a}-{b}' for a, b in spans)


def oversubscription(threads: int, cores: Collection[int] | None = None) -> str | None:
    """Why ``threads`` inference threads are too many for the cores, or None when they fit.

    More threads than cores cannot all run at once: in every sample's torch call they wait for
    each other, and the executor's own thread waits for them (a real-time node misses cycles).

    Args:
        threads: the torch and BLAS threads asked for.
        cores: the CPU cores the process may run on (default: ``cpu_cores()``).
    """
    cores = cpu_cores() if cores is None else cores
    if threads <= len(cores):
        return None
    count, plural = len(cores), 's' * (len(cores) != 1)
    return (
        f'torch_threads {threads} oversubscribes the {count} CPU core{plural} this process may '
        f'run on (core{plural} {_ranges(cores)}): the threads of every sample wait for each '
        'other and the executor waits for them, so IPO cycles can be missed; one sample gains '
        'nothing from more threads: set torch_threads 1'
        + (f' (at most {count})' if count > 1 else '')
    )
