"""Ctrl-C (SIGINT) and SIGTERM stop a command with one line saying what is left where, no
traceback, and the shell's status (128 + the signal's number); a run keeps its partial folder."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO, twin_config

from id_learning.outputs import INCOMPLETE_FILE, partial_path

#: How long a stopped command may take to say so and exit [s].
EXIT_S = 60


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 51.5 s twin bag: long enough to train on through the label filter."""
    from id_learning.twin import simulate, write_twin_output

    config = twin_config(60.0, seed=11)
    return write_twin_output(simulate(config), config, tmp_path_factory.mktemp('bag') / 'twin')


def _cli(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, '-m', 'id_learning.cli', *argv],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=REPO,
    )  # fmt: skip


def _wait_for(process: subprocess.Popen[str], text: str) -> None:
    """Read stderr up to the first line holding ``text`` (the process prints as it goes)."""
    assert process.stderr is not None
    lines = []
    for line in process.stderr:
        lines.append(line)
        if text in line:
            return
    raise AssertionError(f'{text!r} never came (exit {process.wait()}): {"".join(lines)}')


def _stop(process: subprocess.Popen[str], number: int) -> tuple[int, list[str]]:
    """Send the signal; the exit status and the lines printed after it."""
    process.send_signal(number)
    try:
        _, err = process.communicate(timeout=EXIT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        raise
    return process.returncode, [line for line in err.splitlines() if line.strip()]


def test_an_interrupted_train_says_in_one_line_that_its_partial_run_is_left(
    bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / 'run'
    # RNEA+LQ is fitted first and saved at once; the MLP would take minutes.
    process = _cli('train', '--bag', str(bag), '--out', str(out), '--quiet', '--device', 'cpu',
                   '--models', 'rnea_lq,mlp', '--hyper', 'mlp.max_epochs=100000',
                   '--hyper', 'mlp.patience=100000')  # fmt: skip
    try:
        _wait_for(process, 'rnea_lq: fitted')
    except BaseException:
        process.kill()
        process.communicate()
        raise
    status, lines = _stop(process, signal.SIGINT)
    assert status == 130, lines
    assert not any('Traceback' in line for line in lines), lines
    assert len(lines) == 1, lines
    assert lines[0].startswith('id-learning train: interrupted; '), lines
    assert str(partial_path(out)) in lines[0]
    assert '--force' in lines[0]
    assert (partial_path(out) / INCOMPLETE_FILE).is_file()  # kept: it holds a fitted model
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run.partial']  # no lock left


def test_a_simulate_terminated_before_writing_says_nothing_was_written(tmp_path: Path) -> None:
    out = tmp_path / 'bag'
    config = str(REPO / 'config/twin_default.yaml')
    process = _cli('simulate', '--config', config, '--duration', '1000', '--out', str(out))
    assert process.stderr is not None
    try:
        # Its first output (the duration warning, the progress bar) comes seconds before the
        # bag is written (about 20 s for 1000 s).
        assert process.stderr.read(1)
    except BaseException:
        process.kill()
        process.communicate()
        raise
    status, lines = _stop(process, signal.SIGTERM)
    assert status == 143, lines
    assert not any('Traceback' in line for line in lines), lines
    assert lines[-1] == f'id-learning simulate: terminated; nothing was written to {out}', lines
    assert list(tmp_path.iterdir()) == []


def test_the_tool_leaves_the_signal_handlers_as_it_found_them(tmp_path: Path) -> None:
    from id_learning.cli.main import main

    numbers = (signal.SIGINT, signal.SIGTERM)
    before = [signal.getsignal(number) for number in numbers]
    # main may run in a process that goes on (a test, ros2 run's entry point)
    assert main(['inspect', str(tmp_path / 'missing')]) == 2
    assert [signal.getsignal(number) for number in numbers] == before
