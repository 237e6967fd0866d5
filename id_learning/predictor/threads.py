"""Thread counts of torch and numpy's BLAS for one-sample inference.

One sample per call gains nothing from more threads, and on a loaded machine the extra threads
wait for each other.
"""

from __future__ import annotations

import ctypes
import logging
from collections.abc import Iterable

import torch

__all__ = ['configure_inference_threads', 'mapped_libraries', 'set_openblas_threads']

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
