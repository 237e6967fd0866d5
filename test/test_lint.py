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


def test_every_type_ignore_names_its_code_and_reason():
    """A silenced type error says which error and why (mypy checks the code, not the reason)."""
    bare = []
    for path in sorted((REPO / 'id_learning').rglob('*.py')):
        for number, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1):
            if 'type: ignore' not in line:
                continue
            after = line.split('type: ignore', 1)[1]
            has_code = after.startswith('[') and ']' in after
            reason = after.split(']', 1)[1].strip() if has_code else ''
            if not (has_code and reason.startswith('#') and len(reason.lstrip('# ')) >= 10):
                bare.append(f'{path.relative_to(REPO)}:{number}: {line.strip()}')
    assert not bare, 'type: ignore without a code and a reason:\n' + '\n'.join(bare)
