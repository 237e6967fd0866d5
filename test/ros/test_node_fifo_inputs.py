"""A node given a FIFO as a file it reads at start-up ends, naming it; a signal is never lost.

A robot_config or ``--params-file`` that is a FIFO no process writes to once kept a node waiting in
open() without a word, and SIGINT/SIGTERM did not end it (the node notes a signal while it is
made and Python retried the open): only SIGKILL did. Now the robot config's FIFO is refused
(``config_io.read_capped``), a params file must be a regular file before ROS reads it
(``param_ros.params_file_kind``), and a signal ends a wait on a FIFO that a writer holds open
without writing (``config_io.pipe_waits_stop_when``). Each node runs as a user runs it (the
console script's ``python -m id_learning.entry``), with a deadline; every process started here
is ended, killed if need be.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.ros_helpers import STARTUP_S, clean_shared_memory, node_environment, random_domain
from support import sine_recording

from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros

#: Deadline for a node to end after a signal [s] (it closes; a hang fails the test).
SIGNAL_S = 20.0
#: What a FIFO no process writes to is refused as (no writer came, or it ended empty).
NO_WRITER = r'a FIFO \(named pipe\) that (no process writes to|ended before giving a byte)'


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(200), tmp_path_factory.mktemp('fifo') / 'bag')
    return path


def _arguments(node: str, bag: Path, robot_config: Path) -> list[str]:
    """The node's ``-p`` parameters with ``robot_config`` and what else it needs to start."""
    needed = {'replay': f'bag:={bag}', 'predictor': 'artifact:=never_read'}[node]
    return ['-p', needed, '-p', f'robot_config:={robot_config}']


def _start(node: str, ros_args: list[str], tmp_path: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, '-m', 'id_learning.entry', node, '--ros-args', *ros_args],
        env=node_environment(random_domain()),
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        restore_signals=True,
    )


def _end(process: subprocess.Popen[str], deadline_s: float) -> tuple[int, str]:
    """Wait for ``process`` to end by itself within ``deadline_s``; its status and output."""
    try:
        output, _ = process.communicate(timeout=deadline_s)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
        clean_shared_memory()
        pytest.fail(f'still running {deadline_s:g} s on; killed. Its output:\n{output}')
    return process.returncode, output


@pytest.fixture
def started(tmp_path: Path) -> Iterator[list[subprocess.Popen[str]]]:
    """Processes a test starts; any still running at its end is killed."""
    processes: list[subprocess.Popen[str]] = []
    yield processes
    killed = False
    for process in processes:
        if process.poll() is None:
            process.kill()
            process.communicate()
            killed = True
    if killed:
        clean_shared_memory()


@pytest.mark.parametrize('node', ['replay', 'predictor'])
def test_a_robot_config_that_is_a_fifo_nobody_writes_ends_the_node_naming_it(
    node: str, bag: Path, tmp_path: Path, started: list[subprocess.Popen[str]]
) -> None:
    fifo = tmp_path / 'robot.yaml'
    os.mkfifo(fifo)
    started.append(_start(node, _arguments(node, bag, fifo), tmp_path))
    status, output = _end(started[-1], STARTUP_S)
    assert status == 2, output
    assert re.search(rf'{re.escape(str(fifo))}: cannot read config file: {NO_WRITER}', output)
    assert 'Traceback' not in output


def test_a_params_file_that_is_a_fifo_is_refused_before_ros_reads_it(
    tmp_path: Path, started: list[subprocess.Popen[str]]
) -> None:
    fifo = tmp_path / 'params.yaml'
    os.mkfifo(fifo)
    started.append(_start('predictor', ['--params-file', str(fifo)], tmp_path))
    status, output = _end(started[-1], STARTUP_S)
    assert status == 2, output
    assert (
        f'error: predictor: --params-file {fifo}: a FIFO (named pipe), not a regular file; ROS '
        'reads a parameter file more than once' in output
    )
    assert 'Traceback' not in output


def _opened_by(pid: int, path: Path) -> bool:
    """Whether process ``pid`` has ``path`` open (its /proc/PID/fd links)."""
    try:
        links = [os.readlink(entry) for entry in Path(f'/proc/{pid}/fd').iterdir()]
    except OSError:  # it ended, or an fd closed while listed
        return False
    return str(path.resolve()) in links


@pytest.mark.parametrize(
    ('node', 'number'),
    [
        pytest.param('replay', signal.SIGTERM, id='replay-SIGTERM'),
        pytest.param('predictor', signal.SIGINT, id='predictor-SIGINT'),
    ],
)
def test_a_signal_while_the_node_waits_on_a_fifo_ends_it_at_once(
    node: str,
    number: signal.Signals,
    bag: Path,
    tmp_path: Path,
    started: list[subprocess.Popen[str]],
) -> None:
    """The FIFO is held open by a writer (this test) that writes nothing: the node waits."""
    fifo = tmp_path / 'robot.yaml'
    os.mkfifo(fifo)
    held = os.open(fifo, os.O_RDWR | os.O_NONBLOCK)  # a writer that never writes
    try:
        process = _start(node, _arguments(node, bag, fifo), tmp_path)
        started.append(process)
        deadline = time.monotonic() + STARTUP_S
        while not _opened_by(process.pid, fifo):
            try:
                process.wait(timeout=0.05)  # the other condition: the node ended
            except subprocess.TimeoutExpired:
                if time.monotonic() < deadline:
                    continue
            _, output = _end(process, 1.0)
            pytest.fail(f'the node never waited on the FIFO:\n{output}')
        process.send_signal(number)
        sent = time.monotonic()
        status, output = _end(process, SIGNAL_S)
    finally:
        os.close(held)
    assert status == 2, output
    assert time.monotonic() - sent < SIGNAL_S
    assert f'{fifo}: cannot read config file: stopped while waiting for a FIFO' in output
    assert 'Traceback' not in output
