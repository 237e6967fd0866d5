"""The Makefile's settings come from its command line, never from the caller's environment."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from support import REPO

pytestmark = pytest.mark.skipif(shutil.which('make') is None, reason='make is not installed')


def dry_run(*args: str, **env: str) -> str:
    """What `make -n` would run, with extra environment variables."""
    result = subprocess.run(
        ['make', '-n', '-C', str(REPO), *args],
        capture_output=True,
        text=True,
        # Not the make variables of a make that runs these tests: they would pass its settings on.
        env={
            **{
                k: v
                for k, v in os.environ.items()
                if k not in ('MAKEFLAGS', 'MFLAGS', 'MAKELEVEL')
            },
            **env,
        },
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_the_old_names_on_the_command_line_are_refused_naming_the_new_ones():
    result = subprocess.run(['make', '-n', '-C', str(REPO), 'demo', 'OUT=/tmp/x'],
                            capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert result.returncode != 0
    assert 'DEMO_OUT' in result.stderr


def test_environment_variables_named_like_settings_do_not_redirect_the_demo():
    out = dry_run('demo', OUT='/tmp/elsewhere', BAG='/tmp/other_bag', DEMO_OUT='/tmp/env_out')
    assert '--bag bags/default --out out/demo' in out
    assert '/tmp/' not in out


def test_the_command_line_sets_the_demos_bag_and_output():
    out = dry_run('demo', 'DEMO_BAG=/tmp/my_bag', 'DEMO_OUT=/tmp/my_out')
    assert '--bag /tmp/my_bag --out /tmp/my_out' in out
