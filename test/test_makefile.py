"""The Makefile's settings come from its command line, never from the caller's environment.

make runs from anywhere: a checkout under /tmp, or under a folder with a space in its name, and
inside the ``make test`` that runs these tests. So no assertion here reads the checkout's path
into make's output: make is asked not to print its directory, and the paths compared are the
ones a test gives.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from support import REPO

pytestmark = pytest.mark.skipif(shutil.which('make') is None, reason='make is not installed')


def make(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    """``make -n`` in the checkout, with extra environment variables."""
    return subprocess.run(
        ['make', '--no-print-directory', '-n', '-C', str(REPO), *args],
        capture_output=True,
        text=True,
        # Not the make variables of a make that runs these tests: they would pass its settings on.
        env={
            **{
                k: v
                for k, v in os.environ.items()
                if k not in ('MAKEFLAGS', 'MFLAGS', 'MAKELEVEL', 'MAKEOVERRIDES')
            },
            **env,
        },
        timeout=60,
        check=False,
    )


def dry_run(*args: str, **env: str) -> str:
    """What ``make -n`` would run."""
    result = make(*args, **env)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_the_old_names_on_the_command_line_are_refused_naming_the_new_ones():
    result = make('demo', 'OUT=/tmp/x')
    assert result.returncode != 0
    assert 'DEMO_OUT' in result.stderr


def test_environment_variables_named_like_settings_do_not_redirect_the_demo():
    given = {'OUT': '/elsewhere/out', 'BAG': '/elsewhere/bag', 'DEMO_OUT': '/elsewhere/env_out'}
    out = dry_run('demo', **given)
    assert '--bag bags/default --out out/demo' in out
    for name, value in given.items():
        assert value not in out, name
    assert 'Entering directory' not in out


def test_the_command_line_sets_the_demos_bag_and_output():
    out = dry_run('demo', 'DEMO_BAG=/tmp/my_bag', 'DEMO_OUT=/tmp/my_out')
    assert '--bag /tmp/my_bag --out /tmp/my_out' in out
