"""tools/hooks/commit-msg refuses a subject over 72 characters; install_hooks.sh sets it up."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from support import REPO

HOOK = REPO / 'tools/hooks/commit-msg'
INSTALL = REPO / 'tools/install_hooks.sh'

needs_git = pytest.mark.skipif(shutil.which('git') is None, reason='git is not installed')


def run(args: list[str], env: dict[str, str], cwd: Path | None = None):
    return subprocess.run(
        args, cwd=cwd, env=env, capture_output=True, text=True, timeout=60, check=False
    )


def git_env(home: Path) -> dict[str, str]:
    """This machine's environment without its git configuration, and an author for commits."""
    env = {k: v for k, v in os.environ.items() if not k.startswith('GIT_')}
    return {
        **env,
        'HOME': str(home),
        'GIT_CONFIG_GLOBAL': os.devnull,
        'GIT_CONFIG_NOSYSTEM': '1',
        'GIT_AUTHOR_NAME': 'Test',
        'GIT_AUTHOR_EMAIL': 'test@example.com',
        'GIT_COMMITTER_NAME': 'Test',
        'GIT_COMMITTER_EMAIL': 'test@example.com',
    }


def run_hook(tmp_path: Path, message: str) -> subprocess.CompletedProcess[str]:
    """The hook as git runs it: the executable itself, on a message file."""
    path = tmp_path / 'COMMIT_EDITMSG'
    path.write_text(message, encoding='utf-8')
    return subprocess.run(
        [str(HOOK), str(path)],
        cwd=tmp_path,
        env=git_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )


def test_the_hook_is_an_executable_python3_script_without_the_venv():
    assert os.access(HOOK, os.X_OK)
    assert HOOK.read_text(encoding='utf-8').startswith('#!/usr/bin/env python3\n')


ACCEPTED = {
    'ok': 'Predictor: refuse stale references\n\nRMSE 0.41 -> 0.22 N*m on joint 3.\n',
    '72': 'x' * 72 + '\n',
    '72-no-newline': 'x' * 72,
    'blank-lines': '\n\n' + 'x' * 72 + '   \n',  # git drops blank lines and trailing blanks
    'comments': '# Please enter the commit message\n' + 'x' * 72 + '\n# ' + 'y' * 100 + '\n',
    'empty': '',
    'only-comments': '\n\n# only comments: git refuses the empty message itself\n',
    'fixup': 'fixup! ' + 'x' * 72 + '\n',
    'squash-fixup': 'squash! fixup! ' + 'x' * 72 + '\n',
    'merge': "Merge branch 'feature/a-branch-name-that-makes-the-subject-long' into main there\n",
    'unicode-72': 'é' * 72 + '\n',  # characters, not bytes
}
REFUSED = {
    '73': 'x' * 73 + '\n',
    'after-comments': '# a comment first\n\n' + 'x' * 73 + '\nbody\n',
    'fixup-of-73': 'fixup! ' + 'x' * 73 + '\n',
    'merge-by-hand': 'Merge the loops of the trainer into one so each epoch reads its data once',
    'unicode-73': 'é' * 73 + '\n',
}


@pytest.mark.parametrize('message', ACCEPTED.values(), ids=ACCEPTED.keys())
def test_the_hook_accepts_a_subject_of_at_most_72_characters(tmp_path, message):
    result = run_hook(tmp_path, message)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ''


@pytest.mark.parametrize('message', REFUSED.values(), ids=REFUSED.keys())
def test_the_hook_refuses_a_subject_over_72_characters_saying_why(tmp_path, message):
    result = run_hook(tmp_path, message)
    assert result.returncode == 1
    subject = next(
        line for line in message.splitlines() if line.strip() and not line.startswith('#')
    )
    measured = subject.removeprefix('fixup! ')
    assert f'the subject is {len(measured)} characters, the limit is 72' in result.stderr
    assert 'put numbers in the body' in result.stderr
    assert subject in result.stderr


def test_the_hook_ignores_what_follows_the_scissors_line(tmp_path):
    scissors = '# ------------------------ >8 ------------------------\n'
    result = run_hook(tmp_path, f'\n{scissors}diff --git a/{"x" * 100} b/{"x" * 100}\n')
    assert result.returncode == 0, result.stderr


@needs_git
def test_install_hooks_makes_git_refuse_a_long_subject_in_a_checkout(tmp_path):
    checkout = tmp_path / 'a checkout'  # a space in the path, as anywhere
    (checkout / 'tools/hooks').mkdir(parents=True)
    shutil.copy2(INSTALL, checkout / 'tools/install_hooks.sh')
    shutil.copy2(HOOK, checkout / 'tools/hooks/commit-msg')
    env = git_env(tmp_path)

    def git(*args: str) -> subprocess.CompletedProcess[str]:
        return run(['git', *args], env, checkout)

    assert git('init', '-q').returncode == 0
    installed = run(['bash', str(checkout / 'tools/install_hooks.sh')], env)
    assert installed.returncode == 0, installed.stderr
    assert git('config', '--get', 'core.hooksPath').stdout.strip() == 'tools/hooks'
    refused = git('commit', '-q', '--allow-empty', '-m', 'x' * 73)
    assert refused.returncode != 0
    assert 'the limit is 72' in refused.stderr
    accepted = git('commit', '-q', '--allow-empty', '-m', 'x' * 72)
    assert accepted.returncode == 0, accepted.stderr
    assert git('log', '--format=%s').stdout.splitlines() == ['x' * 72]


@needs_git
def test_install_hooks_skips_a_folder_that_is_no_checkout_of_its_own(tmp_path):
    env = git_env(tmp_path)
    outer = tmp_path / 'outer'
    for folder in (tmp_path / 'plain', outer / 'inner'):  # no git; inside another repository
        (folder / 'tools').mkdir(parents=True)
        shutil.copy2(INSTALL, folder / 'tools/install_hooks.sh')
    subprocess.run(['git', 'init', '-q', str(outer)], env=env, check=True, timeout=60)
    for folder in (tmp_path / 'plain', outer / 'inner'):
        result = run(['bash', str(folder / 'tools/install_hooks.sh')], env)
        assert (result.returncode, result.stdout, result.stderr) == (0, '', '')
    assert run(['git', 'config', '--get', 'core.hooksPath'], env, outer).stdout == ''


def test_bootstrap_installs_the_hooks():
    assert 'install_hooks.sh' in (REPO / 'tools/bootstrap_venv.sh').read_text(encoding='utf-8')
