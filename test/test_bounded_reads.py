"""Every file the tool reads whole is bounded, and every file of its own folders must be a file.

A link to ``/dev/zero`` once made ``bag recover`` read until the kernel killed it; a FIFO in a
bag or run folder, which nobody writes, made ``inspect`` and ``evaluate`` wait forever; 60 MB of
comments in a metadata.yaml kept ``inspect`` parsing for minutes; a FIFO nobody writes, given
as a config, mapping, hyper-parameter file, study table, excitation or URDF, kept every command
waiting in open() without a word. Each case runs as a user runs it, in a process of its own with
a deadline and a memory cap: a hang or an unbounded read fails the test instead of the machine,
and the refusal must name the file and what it is. A pipe handed over by the shell (``--robot
<(...)``) is still read, also from a writer that takes its time.
"""

from __future__ import annotations

import os
import re
import resource
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import yaml
from support import REPO, no_hang, sine_recording

from id_learning import bounded_read
from id_learning.bag.metadata_file import MAX_BAG_METADATA_BYTES
from id_learning.dataset.recording import write_recording
from id_learning.errors import ConfigError
from id_learning.evaluation.study import MAX_STUDY_TABLE_BYTES

#: Seconds a refusal may take (the slowest command imports torch: about 3 s).
DEADLINE_S = 60.0
#: Address space of each run [bytes]: reading /dev/zero whole fails fast, not the machine.
MEMORY_CAP = 4 * 2**30

#: A function-level reader run in its own process: the error's text is its only output.
_CALL = """
import sys
from pathlib import Path
from id_learning.errors import IdLearningError
try:
    {call}
except IdLearningError as err:
    print(err, file=sys.stderr)
    sys.exit(2)
print('read without a refusal', file=sys.stderr)
"""


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def _run(argv: list[str]) -> tuple[subprocess.CompletedProcess[str], float]:
    start = time.monotonic()
    try:
        result = subprocess.run(
            [sys.executable, *argv],
            capture_output=True,
            stdin=subprocess.DEVNULL,
            text=True,
            cwd=REPO,
            timeout=DEADLINE_S,
            check=False,
            preexec_fn=_cap_memory,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f'{argv}: no answer within {DEADLINE_S:g} s (it blocks or reads without end)')
    return result, time.monotonic() - start


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_recording(sine_recording(1500), tmp_path_factory.mktemp('bounded') / 'bag')


def _copy(bag: Path, to: Path) -> Path:
    to.mkdir()
    for file in bag.iterdir():
        (to / file.name).write_bytes(file.read_bytes())
    return to


def _storage(folder: Path) -> Path:
    return next(folder.glob('*.mcap'))


def _to_device(file: Path) -> Path:
    file.unlink(missing_ok=True)
    file.symlink_to('/dev/zero')
    return file


def _to_fifo(file: Path) -> Path:
    file.unlink(missing_ok=True)
    os.mkfifo(file)
    return file


def _grow(file: Path, size: int) -> Path:
    """Append comment lines until ``file`` is ``size`` bytes (real bytes: no sparse file)."""
    line = b'# ' + b'x' * 97 + b'\n'
    with file.open('ab') as stream:
        stream.write(line * (size // len(line) + 1))
    return file


def _sparse(file: Path, size: int) -> Path:
    with file.open('wb') as stream:
        stream.truncate(size)
    return file


def _run_folder(tmp: Path, make: Callable[[Path], Path]) -> Path:
    run = tmp / 'run'
    run.mkdir()
    make(run / 'run.json')
    return run


def _ground_truth(bag: Path, tmp: Path, make: Callable[[Path], Path], name: str) -> Path:
    folder = _copy(bag, tmp / 'twin_bag')
    (folder / 'ground_truth.json').write_text('{}')
    (folder / 'ground_truth.npz').write_bytes(b'')
    make(folder / name)
    return folder


def _cli(*args: str) -> list[str]:
    return ['-m', 'id_learning.cli', *args]


def _train(bag: Path, tmp: Path, *extra: str, command: str = 'train') -> list[str]:
    """``train`` (or ``demo``, without its diagnosis) of an MLP on ``bag``, then ``extra``."""
    skip = ['--skip-diagnosis'] if command == 'demo' else []
    return _cli(command, '--bag', str(bag), '--out', str(tmp / 'out'), '--models', 'mlp',
                *skip, *extra)  # fmt: skip


def _evaluate(bag: Path, tmp: Path, run: str) -> list[str]:
    return _cli('evaluate', '--run', run, '--bag', str(bag), '--out', str(tmp / 'out'))


def _call(call: str) -> list[str]:
    return ['-c', _CALL.format(call=call)]


MAPPING = str(REPO / 'config' / 'import_example.yaml')
ROBOT = REPO / 'config' / 'mabi_max100.yaml'
#: What a FIFO no process writes to is refused as (no writer came, or it ended empty).
NO_WRITER = r'a FIFO \(named pipe\) that (no process writes to|ended before giving a byte)'


def _robot_text() -> str:
    """The MABI robot config with its URDF as an absolute path (read from anywhere, a pipe too)."""
    text = ROBOT.read_text(encoding='utf-8')
    return text.replace('../urdf/', f'{REPO / "urdf"}/')


def _robot_with_fifo_urdf(tmp: Path) -> Path:
    """A robot config whose ``urdf:`` is a FIFO nobody writes."""
    (tmp / 'robot').mkdir()
    text = ROBOT.read_text(encoding='utf-8').replace('../urdf/mabi_max100.urdf', 'arm.urdf')
    (tmp / 'robot' / 'robot.yaml').write_text(text, encoding='utf-8')
    _to_fifo(tmp / 'robot' / 'arm.urdf')
    return tmp / 'robot' / 'robot.yaml'


def _twin_with_fifo_excitation(tmp: Path) -> Path:
    """The default twin config whose ``excitation: {file: ...}`` is a FIFO nobody writes."""
    data = yaml.safe_load((REPO / 'config' / 'twin_default.yaml').read_text(encoding='utf-8'))
    data['robot'] = str(ROBOT)
    data['excitation'] = {'file': str(_to_fifo(tmp / 'excitation.json'))}
    (tmp / 'twin.yaml').write_text(yaml.safe_dump(data), encoding='utf-8')
    return tmp / 'twin.yaml'


def _log_csv(tmp: Path) -> Path:
    (tmp / 'log.csv').write_text('t,q\n0,0\n', encoding='utf-8')
    return tmp / 'log.csv'


# Each case: (how to build what is read, in tmp) -> (argv, the refusal's words as a pattern).
CASES: dict[str, Callable[[Path, Path], tuple[list[str], str]]] = {
    'inspect, metadata.yaml a link to /dev/zero': lambda bag, tmp: (
        _cli('inspect', str(_to_device(_copy(bag, tmp / 'b') / 'metadata.yaml').parent)),
        r'b/metadata\.yaml: a character device, not a regular file',
    ),
    'inspect, metadata.yaml a FIFO': lambda bag, tmp: (
        _cli('inspect', str(_to_fifo(_copy(bag, tmp / 'b') / 'metadata.yaml').parent)),
        r'b/metadata\.yaml: a FIFO \(named pipe\), not a regular file',
    ),
    'inspect, the .mcap a FIFO nobody writes': lambda bag, tmp: (
        _cli('inspect', str(_to_fifo(_storage(_copy(bag, tmp / 'b'))).parent)),
        r'b/bag_0\.mcap: a FIFO \(named pipe\), not a regular file',
    ),
    'inspect, metadata.yaml grown past its cap': lambda bag, tmp: (
        _cli(
            'inspect',
            str(_grow(_copy(bag, tmp / 'b') / 'metadata.yaml', MAX_BAG_METADATA_BYTES).parent),
        ),
        r'b/metadata\.yaml: cannot read bag metadata: larger than 4 MiB',
    ),
    'inspect /dev/zero': lambda bag, tmp: (
        _cli('inspect', '/dev/zero'),
        r'^id-learning inspect: error: /dev/zero: a character device, not a bag folder',
    ),
    'inspect a FIFO given as the bag': lambda bag, tmp: (
        _cli('inspect', str(_to_fifo(tmp / 'pipe'))),
        r'pipe: a FIFO \(named pipe\), not a bag folder',
    ),
    'bag recover, metadata.yaml a link to /dev/zero': lambda bag, tmp: (
        _cli(
            'bag',
            'recover',
            str(_to_device(_copy(bag, tmp / 'b') / 'metadata.yaml').parent),
            '--out',
            str(tmp / 'out'),
        ),
        r'b/metadata\.yaml: a character device, not a regular file',
    ),
    'train, metadata.yaml a link to /dev/zero': lambda bag, tmp: (
        _train(_to_device(_copy(bag, tmp / 'b') / 'metadata.yaml').parent, tmp),
        r'b/metadata\.yaml: a character device, not a regular file',
    ),
    'bag recover /dev/zero': lambda bag, tmp: (
        _cli('bag', 'recover', '/dev/zero'),
        r'/dev/zero: a character device, not a bag folder',
    ),
    'train --study-table /dev/urandom': lambda bag, tmp: (
        _train(bag, tmp, '--study-table', '/dev/urandom'),
        r'/dev/urandom: cannot read study table: a character device, not a regular file',
    ),
    'train --study-table past its cap': lambda bag, tmp: (
        _train(
            bag, tmp, '--study-table', str(_sparse(tmp / 'big.json', MAX_STUDY_TABLE_BYTES + 1))
        ),
        r'big\.json: cannot read study table: larger than 1 MiB',
    ),
    'demo --study-table /dev/zero': lambda bag, tmp: (
        _train(bag, tmp, '--study-table', '/dev/zero', command='demo'),
        r'/dev/zero: cannot read study table: a character device',
    ),
    'evaluate, run.json a FIFO': lambda bag, tmp: (
        _evaluate(bag, tmp, str(_run_folder(tmp, _to_fifo))),
        r'run/run\.json: cannot read run document: a FIFO \(named pipe\), not a regular file',
    ),
    'evaluate, run.json a link to /dev/zero': lambda bag, tmp: (
        _evaluate(bag, tmp, str(_run_folder(tmp, _to_device))),
        r'run/run\.json: cannot read run document: a character device',
    ),
    'evaluate --run /dev/zero': lambda bag, tmp: (
        _evaluate(bag, tmp, '/dev/zero'),
        r'/dev/zero: a character device, not a training run folder',
    ),
    'import /dev/urandom': lambda bag, tmp: (
        _cli('import', '/dev/urandom', '--mapping', MAPPING, '--out', str(tmp / 'i')),
        r'/dev/urandom: a character device, not a log file or folder',
    ),
    'import a FIFO': lambda bag, tmp: (
        _cli(
            'import', str(_to_fifo(tmp / 'log.csv')), '--mapping', MAPPING, '--out', str(tmp / 'i')
        ),
        r'log\.csv: a FIFO \(named pipe\), not a log file or folder; an import reads a log',
    ),
    'read_ground_truth, ground_truth.json a link to /dev/zero': lambda bag, tmp: (
        _call(
            'from id_learning.twin.ground_truth import read_ground_truth; '
            f'read_ground_truth({str(_ground_truth(bag, tmp, _to_device, "ground_truth.json"))!r}'
            ", 'motor')"
        ),
        r'twin_bag/ground_truth\.json: a character device, not a regular file',
    ),
    'read_ground_truth, ground_truth.npz a FIFO': lambda bag, tmp: (
        _call(
            'from id_learning.twin.ground_truth import read_ground_truth; '
            f'read_ground_truth({str(_ground_truth(bag, tmp, _to_fifo, "ground_truth.npz"))!r}'
            ", 'motor')"
        ),
        r'twin_bag/ground_truth\.npz: a FIFO \(named pipe\), not a regular file',
    ),
    'read_metadata, model.json a FIFO': lambda bag, tmp: (
        _call(
            'from id_learning.models.artifact import read_metadata; '
            f'read_metadata(Path({str(_to_fifo(tmp / "model.json"))!r}))'
        ),
        r'model\.json: cannot read model metadata: a FIFO \(named pipe\), not a regular file',
    ),
    'load_effects_file, effects.json a FIFO': lambda bag, tmp: (
        _call(
            'from id_learning.models.effects import load_effects_file; '
            f'load_effects_file({str(_to_fifo(tmp / "effects.json"))!r})'
        ),
        r'effects\.json: cannot read effects\.json: a FIFO \(named pipe\), not a regular file',
    ),
    'load_effects_file, effects.json a link to /dev/zero': lambda bag, tmp: (
        _call(
            'from id_learning.models.effects import load_effects_file; '
            f'load_effects_file({str(_to_device(tmp / "effects.json"))!r})'
        ),
        r'effects\.json: cannot read effects\.json: a character device',
    ),
    'bag_custom_data, metadata.yaml a socket': lambda bag, tmp: (
        _call(
            'from id_learning.bag import bag_custom_data; '
            f'bag_custom_data({str(_socket_metadata(bag, tmp))!r})'
        ),
        r'b/metadata\.yaml: cannot read bag metadata: a socket, not a regular file',
    ),
    'simulate --config a FIFO nobody writes': lambda bag, tmp: (
        _cli(
            'simulate',
            '--config',
            str(_to_fifo(tmp / 'twin.yaml')),
            '--out',
            str(tmp / 's'),
            '--duration',
            '5',
            '--quiet',
        ),
        rf'twin\.yaml: cannot read config file: {NO_WRITER}',
    ),
    "simulate, the twin config's excitation.file a FIFO nobody writes": lambda bag, tmp: (
        _cli(
            'simulate',
            '--config',
            str(_twin_with_fifo_excitation(tmp)),
            '--out',
            str(tmp / 's'),
            '--quiet',
        ),
        rf'excitation\.json: cannot read a designed excitation: {NO_WRITER}',
    ),
    'train --hyper-file a FIFO nobody writes': lambda bag, tmp: (
        _train(bag, tmp, '--hyper-file', str(_to_fifo(tmp / 'hyper.yaml'))),
        rf'hyper\.yaml: cannot read config file: {NO_WRITER}',
    ),
    'train --study-table a FIFO nobody writes': lambda bag, tmp: (
        _train(bag, tmp, '--study-table', str(_to_fifo(tmp / 'study.json'))),
        rf'study\.json: cannot read study table: {NO_WRITER}',
    ),
    'inspect --robot a FIFO nobody writes': lambda bag, tmp: (
        _cli('inspect', str(bag), '--robot', str(_to_fifo(tmp / 'robot.yaml'))),
        rf'robot\.yaml: cannot read config file: {NO_WRITER}',
    ),
    "inspect --robot, the robot config's urdf a FIFO nobody writes": lambda bag, tmp: (
        _cli('inspect', str(bag), '--robot', str(_robot_with_fifo_urdf(tmp))),
        r'robot/arm\.urdf: cannot read URDF: a FIFO \(named pipe\), not a regular file',
    ),
    'import --mapping a FIFO nobody writes': lambda bag, tmp: (
        _cli(
            'import',
            str(_log_csv(tmp)),
            '--mapping',
            str(_to_fifo(tmp / 'map.yaml')),
            '--out',
            str(tmp / 'i'),
        ),
        rf'map\.yaml: cannot read config file: {NO_WRITER}',
    ),
}


def _socket_metadata(bag: Path, tmp: Path) -> Path:
    folder = _copy(bag, tmp / 'b')
    (folder / 'metadata.yaml').unlink()
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(folder / 'metadata.yaml'))  # the file stays when the socket closes
    server.close()
    return folder


@pytest.mark.parametrize('case', list(CASES))
def test_a_file_that_is_no_file_or_too_large_is_refused_at_once_naming_it(
    case: str, bag: Path, tmp_path: Path
) -> None:
    argv, expected = CASES[case](bag, tmp_path)
    result, elapsed = _run(argv)
    assert result.returncode != 0, result.stderr
    assert re.search(expected, result.stderr, re.MULTILINE), result.stderr
    assert 'Traceback' not in result.stderr
    assert 'bag recover' not in result.stderr  # a device or a pipe is no torn recording
    assert elapsed < DEADLINE_S


def test_judging_what_an_output_folder_holds_reads_no_file_without_end(
    bag: Path, tmp_path: Path
) -> None:
    """--force over a bag whose metadata.yaml is /dev/zero: judged (a bag) without reading it."""
    target = _to_device(_copy(bag, tmp_path / 'b') / 'metadata.yaml').parent
    config = REPO / 'config' / 'twin_default.yaml'
    argv = _cli('simulate', '--config', str(config), '--out', str(target), '--force')
    result, _ = _run([*argv, '--duration', '5', '--quiet'])
    assert 'Traceback' not in result.stderr, result.stderr
    assert result.returncode == 0, result.stderr
    assert (target / 'metadata.yaml').is_file()
    assert not (target / 'metadata.yaml').is_symlink()


# -- pipes handed over by the shell ---------------------------------------------------------------
def _bash(command: str, tmp: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    """``command`` run by bash (``<(...)`` is bash's), ``$PY`` this Python, with a deadline."""
    start = time.monotonic()
    try:
        result = subprocess.run(
            ['bash', '-c', command],
            capture_output=True,
            stdin=subprocess.DEVNULL,
            text=True,
            cwd=REPO,
            env={**os.environ, 'PY': sys.executable, 'ROBOT_TEXT': str(tmp / 'robot.txt')},
            timeout=DEADLINE_S,
            check=False,
            preexec_fn=_cap_memory,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f'{command}: no answer within {DEADLINE_S:g} s (it blocks)')
    return result, time.monotonic() - start


@pytest.mark.parametrize(
    'writer',
    [
        'cat "$ROBOT_TEXT"',
        # A writer that holds the pipe open and starts writing late (a script that imports
        # first): waited on for longer than a FIFO that no process writes to is.
        f'sleep {bounded_read.PIPE_WRITER_S + 1:g}; cat "$ROBOT_TEXT"',
    ],
)
def test_a_robot_config_given_by_process_substitution_is_read(
    writer: str, bag: Path, tmp_path: Path
) -> None:
    (tmp_path / 'robot.txt').write_text(_robot_text(), encoding='utf-8')
    result, _ = _bash(f'"$PY" -m id_learning.cli inspect {bag} --robot <({writer})', tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    assert 'FIFO' not in result.stdout + result.stderr


def test_a_process_substitution_that_gives_nothing_is_refused_naming_it(
    bag: Path, tmp_path: Path
) -> None:
    result, elapsed = _bash(f'"$PY" -m id_learning.cli inspect {bag} --robot <(true)', tmp_path)
    assert result.returncode != 0
    assert re.search(rf'/dev/fd/\d+: cannot read config file: {NO_WRITER}', result.stderr), (
        result.stderr
    )
    assert 'Traceback' not in result.stderr
    assert elapsed < DEADLINE_S


# -- the pipe reader itself, in this process ------------------------------------------------------
#: Seconds a read in this process may take before the test fails (SIGALRM ends a blocked open()).
IN_PROCESS_S = 20.0


@pytest.fixture
def deadline() -> Iterator[None]:
    """Fail, not hang, when a read in this process blocks."""
    with no_hang(IN_PROCESS_S):
        yield


def _held_fifo(tmp: Path) -> tuple[Path, int]:
    """A FIFO held open for writing (here: O_RDWR never blocks) that is never written to."""
    path = _to_fifo(tmp / 'held.yaml')
    return path, os.open(path, os.O_RDWR | os.O_NONBLOCK)


@pytest.mark.usefixtures('deadline')
def test_a_fifo_whose_writer_gives_nothing_is_refused_after_the_idle_wait(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(bounded_read, 'PIPE_IDLE_S', 0.5)
    path, held = _held_fifo(tmp_path)
    try:
        os.write(held, b'a: ')  # a start, then nothing more and no end
        start = time.monotonic()
        with pytest.raises(ConfigError) as err:
            bounded_read.read_capped(path, 'robot config')
        elapsed = time.monotonic() - start
    finally:
        os.close(held)
    assert str(err.value) == (
        f'{path}: cannot read robot config: a FIFO (named pipe) whose writer gave no byte for '
        '0.5 s and kept it open: is the writer stuck? (3 bytes came before)'
    )
    assert 0.5 <= elapsed < 5.0


@pytest.mark.usefixtures('deadline')
def test_a_wait_on_a_fifo_ends_when_a_stop_is_asked_for(tmp_path: Path) -> None:
    """What a node does with SIGINT/SIGTERM while it starts: noted, and the wait ends at once."""
    path, held = _held_fifo(tmp_path)
    stop = threading.Event()
    timer = threading.Timer(0.3, stop.set)
    timer.start()
    try:
        start = time.monotonic()
        with bounded_read.pipe_waits_stop_when(stop.is_set), pytest.raises(ConfigError) as err:
            bounded_read.read_capped(path, 'robot config')
        elapsed = time.monotonic() - start
    finally:
        timer.cancel()
        os.close(held)
    assert str(err.value) == (
        f'{path}: cannot read robot config: stopped while waiting for a FIFO (named pipe)'
    )
    assert elapsed < bounded_read.PIPE_WRITER_S
    assert bounded_read._PIPE_STOPS == []


@pytest.mark.usefixtures('deadline')
def test_a_fifo_no_process_writes_to_is_refused_within_the_writer_wait(tmp_path: Path) -> None:
    path = _to_fifo(tmp_path / 'robot.yaml')
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:
        bounded_read.read_capped(path, 'robot config')
    assert str(err.value) == (
        f'{path}: cannot read robot config: a FIFO (named pipe) that no process writes to'
    )
    assert time.monotonic() - start < bounded_read.PIPE_WRITER_S + 3.0


@pytest.mark.usefixtures('deadline')
def test_a_fifo_whose_writer_comes_a_moment_later_is_read(tmp_path: Path) -> None:
    path = _to_fifo(tmp_path / 'robot.yaml')
    opened = threading.Event()

    def write_late() -> None:
        opened.wait(5.0)
        with path.open('wb') as stream:
            stream.write(b'name: late\n')

    writer = threading.Thread(target=write_late, daemon=True)
    writer.start()
    # The reader opens first: no writer yet, so read() says 0, which is no end yet.
    timer = threading.Timer(0.3, opened.set)
    timer.start()
    try:
        assert bounded_read.read_capped(path) == b'name: late\n'
    finally:
        timer.cancel()
        opened.set()
        writer.join(5.0)
    assert not writer.is_alive()


@pytest.mark.usefixtures('deadline')
def test_a_fifo_whose_writer_closes_it_without_a_byte_is_refused_at_once(tmp_path: Path) -> None:
    path, held = _held_fifo(tmp_path)
    threading.Timer(0.3, os.close, args=(held,)).start()
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:
        bounded_read.read_capped(path, 'robot config')
    assert str(err.value) == (
        f'{path}: cannot read robot config: a FIFO (named pipe) that ended before giving a byte'
    )
    assert time.monotonic() - start < bounded_read.PIPE_WRITER_S
