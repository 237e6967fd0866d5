"""numpy's OpenBLAS is found and its thread count set, wherever the venv lies."""

from __future__ import annotations

import subprocess
import sys

import pytest
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
