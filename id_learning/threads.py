"""One BLAS thread for the many small dense solves of the identification and the diagnosis.

OpenBLAS keeps its worker threads spinning between calls. On a shared 2-core machine, with two
other processes busy, a 119 x 119 ``numpy.linalg.solve`` took 0.19 s on OpenBLAS's default
threads and 0.5 ms on one; the identification's geometry search makes hundreds of such solves.
Their matrices are small, so one thread loses nothing when the machine is idle.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from typing import ParamSpec, TypeVar

__all__ = ['single_blas_thread']

_P = ParamSpec('_P')
_R = TypeVar('_R')


def single_blas_thread(function: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``function`` with the BLAS and LAPACK libraries limited to one thread."""

    @wraps(function)
    def limited(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        # threadpoolctl ships no type information.
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api='blas'):
            return function(*args, **kwargs)

    return limited
