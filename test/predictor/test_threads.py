"""numpy's OpenBLAS is found and its thread count set, wherever the venv lies."""

from __future__ import annotations

import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import REPO

from id_learning.predictor.threads import mapped_libraries

MAPS = [
    '7f0c1a000000-7f0c1a200000 r-xp 00000000 fd:01 123 /usr/lib/libc.so.6\n',
    '7f0c1b000000-7f0c1b400000 r-xp 00000000 fd:01 456 '
    '/home/a user/my project/.venv/lib/python3.11/site-packages/numpy.libs/'
    'libscipy_openblas64_-32a4b2a6.so\n',
    '7f0c1c000000-7f0c1c001000 rw-p 00000000 00:00 0 \n',
    '7f0c1d000000-7f0c1d400000 r-xp 00000000 fd:01 789                  /opt/libOpenBLAS.so.0\n',
]


def test_mapped_libraries_keep_paths_with_spaces_whole():
    assert mapped_libraries(MAPS, 'openblas') == {
        '/home/a user/my project/.venv/lib/python3.11/site-packages/numpy.libs/'
        'libscipy_openblas64_-32a4b2a6.so',
        '/opt/libOpenBLAS.so.0',
    }
    assert mapped_libraries(MAPS, 'libc.so') == {'/usr/lib/libc.so.6'}


def test_the_openblas_numpy_loaded_gets_its_thread_count_set():
    code = (
        'import numpy, threadpoolctl\n'
        'from id_learning.predictor.threads import set_openblas_threads\n'
        "apis = {i['internal_api'] for i in threadpoolctl.threadpool_info()}\n"
        "print('openblas' in apis, set_openblas_threads(1))\n"
    )
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            cwd=REPO, timeout=120, check=False)  # fmt: skip
    assert result.returncode == 0, result.stderr
    has_openblas, was_set = result.stdout.split()
    if has_openblas != 'True':
        pytest.skip('numpy here is built without OpenBLAS: nothing to set')
    assert was_set == 'True'


# -- more threads than cores ----------------------------------------------------------------------
def _cores_of(text: str) -> set[int]:
    """The cores an oversubscription message names ('cores 0-3, 6')."""
    named = text.split('(core', 1)[1].split(')', 1)[0].lstrip('s ')
    cores: set[int] = set()
    for item in named.split(', '):
        low, _, high = item.partition('-')
        cores.update(range(int(low), int(high or low) + 1))
    return cores


@settings(max_examples=200, deadline=None)
@given(cores=st.sets(st.integers(0, 255), min_size=1, max_size=64), threads=st.integers(1, 256))
def test_threads_beyond_the_cores_are_said_naming_every_core_and_others_are_not(cores, threads):
    from id_learning.predictor.threads import oversubscription

    said = oversubscription(threads, cores)
    if threads <= len(cores):
        assert said is None
        return
    assert said is not None
    assert said.startswith(f'torch_threads {threads} oversubscribes the {len(cores)} CPU core')
    assert _cores_of(said) == cores
    assert 'set torch_threads 1' in said


def test_the_cores_are_those_this_process_may_run_on():
    import os

    from id_learning.predictor.threads import cpu_cores, oversubscription

    assert cpu_cores() == os.sched_getaffinity(0)
    assert oversubscription(1) is None
    assert oversubscription(len(cpu_cores()) + 1) is not None
