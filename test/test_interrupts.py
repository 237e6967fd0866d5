"""Ctrl-C (SIGINT) and SIGTERM stop a command with one line saying what is left where, no
traceback, and the shell's status (128 + the signal's number); a run keeps its partial folder."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import time
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


#: Runs the rest of its command line with SIGINT and SIGTERM at their defaults, as a terminal's
#: foreground job has them: a suite started in the background (``nohup ... &``) passes SIGINT
#: on ignored, and a program leaves an ignored signal ignored (as Python itself does).
AS_FROM_A_TERMINAL = [
    sys.executable, '-c',
    'import os, signal, sys\n'
    'for number in (signal.SIGINT, signal.SIGTERM): signal.signal(number, signal.SIG_DFL)\n'
    'os.execv(sys.executable, [sys.executable, *sys.argv[1:]])',
]  # fmt: skip


def _cli(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*AS_FROM_A_TERMINAL, '-m', 'id_learning.cli', *argv],
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


def _train_with_a_fitted_model(bag: Path, out: Path) -> subprocess.Popen[str]:
    """A train into ``out`` once it has fitted and saved RNEA+LQ; its MLP would take minutes."""
    process = _cli('train', '--bag', str(bag), '--out', str(out), '--quiet', '--device', 'cpu',
                   '--models', 'rnea_lq,mlp', '--hyper', 'mlp.max_epochs=100000',
                   '--hyper', 'mlp.patience=100000')  # fmt: skip
    try:
        _wait_for(process, 'rnea_lq: fitted')
    except BaseException:
        process.kill()
        process.communicate()
        raise
    return process


def test_an_interrupted_train_says_in_one_line_that_its_partial_run_is_left(
    bag: Path, tmp_path: Path
) -> None:
    out = tmp_path / 'run'
    process = _train_with_a_fitted_model(bag, out)
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


def test_ctrl_c_pressed_again_and_again_during_the_cleanup_changes_nothing(
    bag: Path, tmp_path: Path
) -> None:
    # The probe's I08: a second SIGINT while the first one's cleanup ran ended train by signal.
    out = tmp_path / 'run'
    process = _train_with_a_fitted_model(bag, out)
    try:
        deadline = time.monotonic() + EXIT_S
        while process.poll() is None:  # a signal every 10 ms until it has exited
            assert time.monotonic() < deadline, 'train did not exit'
            process.send_signal(signal.SIGINT)
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(0.01)
    except BaseException:
        process.kill()
        process.communicate()
        raise
    _, err = process.communicate(timeout=EXIT_S)
    lines = [line for line in err.splitlines() if line.strip()]
    assert process.returncode == 130, lines
    assert not any('Traceback' in line for line in lines), lines
    assert len(lines) == 1, lines
    assert lines[0].startswith('id-learning train: interrupted; '), lines
    assert (partial_path(out) / INCOMPLETE_FILE).is_file()


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


# -- while a program imports (id_learning/entry.py) ---------------------------------------------
#: A program that says when it is importing, then imports for a minute.
SLOW_PROGRAM = """
import sys, time
print('importing', file=sys.stderr, flush=True)
time.sleep(60)
def main():
    return 0
"""


def _slow_start(tmp_path: Path) -> subprocess.Popen[str]:
    """``id_learning.entry.run`` of a program that is importing when it says so."""
    (tmp_path / 'slow_program.py').write_text(SLOW_PROGRAM)
    code = (
        f'import sys; sys.path.insert(0, {str(tmp_path)!r}); import id_learning.entry as entry; '
        "entry.PROGRAMS['slow'] = ('slow_program', 'main'); sys.exit(entry.run('slow'))"
    )
    return subprocess.Popen(
        [*AS_FROM_A_TERMINAL, '-c', code], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
        text=True, cwd=REPO,
    )  # fmt: skip


@pytest.mark.parametrize(
    ('number', 'status', 'word'),
    [
        (signal.SIGINT, 130, 'interrupted'),
        (signal.SIGTERM, 143, 'terminated'),
        (signal.SIGHUP, 129, 'hung up (SIGHUP)'),  # probe 16 D17: died without a line
    ],
)
def test_a_signal_while_a_program_imports_is_one_line_and_the_shells_status(
    tmp_path: Path, number: int, status: int, word: str
) -> None:
    process = _slow_start(tmp_path)
    try:
        _wait_for(process, 'importing')
    except BaseException:
        process.kill()
        process.communicate()
        raise
    code, lines = _stop(process, number)
    assert code == status, lines
    assert lines == [f'slow: {word} while starting; nothing was done'], lines


def test_every_console_script_starts_through_the_entry_module() -> None:
    """Each imports its program only inside the handling (setup.py's console_scripts)."""
    from id_learning.entry import PROGRAMS

    setup = (REPO / 'setup.py').read_text()
    for name in PROGRAMS:
        function = 'cli' if name == 'id-learning' else name
        assert f"'{name} = id_learning.entry:{function}'" in setup, name


def _loaded(pid: int, library: str, deadline_s: float = 120.0) -> bool:
    """Wait until the process has loaded a shared library (False: it ended first)."""
    maps = Path(f'/proc/{pid}/maps')
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            if library in maps.read_text():
                return True
        except OSError:  # it has ended
            return False
        time.sleep(0.002)  # a poll of the condition, not a wait for time to pass
    raise AssertionError(f'{library} not loaded by pid {pid} within {deadline_s:g} s')


@pytest.mark.ros
@pytest.mark.parametrize(
    ('node', 'parameters', 'library'),
    [
        ('predictor', ['-p', 'artifact:=/nonexistent/model'], '_rclpy_pybind11'),
        ('predictor', ['-p', 'artifact:=/nonexistent/model'], 'libtorch'),
        ('recorder', ['-p', 'output:=OUT'], '_rclpy_pybind11'),
    ],
)
def test_ctrl_c_while_a_node_starts_is_one_line_never_a_traceback(
    tmp_path: Path, node: str, parameters: list[str], library: str
) -> None:
    """The probe's traceback at 0.3, 0.5 and 1.5 s: SIGINT at each stage of a node's start."""
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    from ros.ros_helpers import node_environment, random_domain

    words = [word.replace('OUT', str(tmp_path / 'bag')) for word in parameters]
    process = subprocess.Popen(
        [*AS_FROM_A_TERMINAL, '-m', 'id_learning.entry', node, '--ros-args', *words],
        env=node_environment(random_domain()), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, cwd=tmp_path,
    )  # fmt: skip
    try:
        assert _loaded(process.pid, library), process.communicate()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=EXIT_S)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    lines = [line for line in (out + err).splitlines() if line.strip()]
    assert 'Traceback' not in out + err, lines
    if process.returncode == 130:  # still importing or starting ROS
        assert lines == [f'{node}: interrupted while starting; nothing was done'], lines
    else:  # it got as far as its parameters (the artifact is refused), or up and stopped
        assert process.returncode in (0, 2), lines
    if node == 'recorder' and process.returncode == 130:
        assert not (tmp_path / 'bag').exists()
