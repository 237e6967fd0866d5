"""Lint as a test (in place of ament_flake8/pep257): ruff with the project's rules."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

RUFF = Path(sys.executable).parent / 'ruff'


@pytest.mark.parametrize('mode', [['check'], ['format', '--check']])
def test_code_is_ruff_clean(mode):
    ruff = RUFF if RUFF.exists() else shutil.which('ruff')
    if ruff is None:
        pytest.skip('ruff is not installed (make test installs it)')
    paths = [
        p
        for p in ('id_learning', 'test', 'benchmarks', 'tools', 'setup.py')
        if (REPO / p).exists()
    ]
    result = subprocess.run(
        [str(ruff), *mode, *paths],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
