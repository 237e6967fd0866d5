"""An import or a simulation stopped while it writes leaves no bag that looks complete (L04/L05).

The bag is written beside ``--out`` (``staged_bag``) and moved there once whole: a Ctrl-C leaves
``--out`` as it was, a kill leaves only a hidden folder the next import removes.
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_interrupts import EXIT_S, _stop

from id_learning.errors import ConfigError
from id_learning.outputs import LOCK_SUFFIX, OutputError
from id_learning.staged_bag import staged_bag, staging_folder

REPO = Path(__file__).resolve().parents[2]
#: How long the import may take to start writing [s].
START_S = 120.0
#: Messages written before the writer waits for the test's signal (of N_ROWS: one a row).
PAUSE_AFTER = 100
N_ROWS = 400

#: The CLI, with the bag writer waiting for a signal once it has written ``PAUSE_AFTER``
#: messages: the test stops it while the bag is half written, whatever the machine's speed.
#: SIGINT and SIGTERM at their terminal defaults (a suite run in the background ignores them).
WRITER_WAITS = f"""
import signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
signal.signal(signal.SIGTERM, signal.SIG_DFL)
from id_learning.bag.writer import BagWriter
from id_learning.cli.main import main
write, written = BagWriter.write, [0]
def waiting(self, *args, **kwargs):
    write(self, *args, **kwargs)
    written[0] += 1
    if written[0] == {PAUSE_AFTER}:
        print('half written', file=sys.stderr, flush=True)
        signal.pause()
BagWriter.write = waiting
sys.exit(main(sys.argv[1:]))
"""


@pytest.fixture
def log(tmp_path: Path) -> tuple[Path, Path]:
    """A 3.2 s CSV log of the MABI's six joints (consistent sines) and its mapping."""
    t = np.arange(N_ROWS) * 0.008
    phase = 2 * np.pi * 0.5 * t[:, None] + np.arange(6)
    q, v = 0.1 * np.sin(phase), 0.1 * np.pi * np.cos(phase)
    header = ['t', *(f'q{j}' for j in range(1, 7)), *(f'v{j}' for j in range(1, 7))]
    rows = np.column_stack([t * 1e3, q, v])
    csv = tmp_path / 'log.csv'
    csv.write_text(
        ','.join(header) + '\n' + ''.join(','.join(map(repr, row.tolist())) + '\n' for row in rows)
    )
    joints = ''.join(
        f'  - name: joint_{j}\n    position: {{column: q{j}, unit: rad}}\n'
        f'    velocity: {{column: v{j}, unit: rad/s}}\n'
        for j in range(1, 7)
    )
    mapping = tmp_path / 'map.yaml'
    mapping.write_text(f'time: {{column: t, unit: ms}}\njoints:\n{joints}')
    return csv, mapping


def _import(log: tuple[Path, Path], out: Path, *extra: str) -> list[str]:
    return ['import', str(log[0]), '--mapping', str(log[1]), '--out', str(out), *extra]


def _half_written(argv: list[str]) -> subprocess.Popen[str]:
    """The CLI started, returned once its bag writer waits half-way (a deadline, no sleep)."""
    process = subprocess.Popen(
        [sys.executable, '-c', WRITER_WAITS, *argv],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO,
    )  # fmt: skip
    assert process.stderr is not None
    seen = b''
    deadline = time.monotonic() + START_S
    with selectors.DefaultSelector() as selector:
        selector.register(process.stderr, selectors.EVENT_READ)
        while b'half written' not in seen:
            left = deadline - time.monotonic()
            chunk = os.read(process.stderr.fileno(), 4096) if selector.select(left) else None
            if not chunk:  # the deadline passed (None), or the command ended (b'')
                process.kill()
                _, rest = process.communicate(timeout=EXIT_S)
                raise AssertionError(f'never wrote half the bag: {seen.decode()}{rest}')
            seen += chunk
    return process


def _cli(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'id_learning.cli', *argv],
        capture_output=True, text=True, cwd=REPO, timeout=START_S, check=False,
    )  # fmt: skip


def test_an_import_interrupted_while_writing_leaves_no_bag_and_says_so(
    log: tuple[Path, Path], tmp_path: Path
) -> None:
    out = tmp_path / 'bag'
    status, lines = _stop(_half_written(_import(log, out)), signal.SIGINT)
    assert status == 130, lines
    assert lines == [f'id-learning import: interrupted; nothing was written to {out}'], lines
    assert not out.exists()  # before the fix: a bag of 50 samples, its metadata.yaml written
    assert sorted(path.name for path in tmp_path.iterdir()) == ['log.csv', 'map.yaml']
    # The rerun finds nothing in its way and writes the whole log.
    rerun = _cli(*_import(log, out))
    assert rerun.returncode == 0, rerun.stderr
    inspect = _cli('inspect', str(out))
    assert inspect.returncode == 0, inspect.stderr
    assert f'{N_ROWS}' in inspect.stdout


def test_an_interrupted_forced_import_keeps_the_bag_it_was_to_replace(
    log: tuple[Path, Path], tmp_path: Path
) -> None:
    out = tmp_path / 'bag'
    assert _cli(*_import(log, out)).returncode == 0
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    status, lines = _stop(_half_written(_import(log, out, '--force')), signal.SIGTERM)
    assert status == 143, lines
    assert lines[-1] == f'id-learning import: terminated; nothing was written to {out}', lines
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before
    assert not staging_folder(out).exists()


def test_a_killed_import_leaves_only_a_hidden_folder_that_the_rerun_removes_saying_so(
    log: tuple[Path, Path], tmp_path: Path
) -> None:
    out = tmp_path / 'bag'
    process = _half_written(_import(log, out))
    process.kill()  # SIGKILL: no handler runs, nothing is cleaned up
    process.communicate(timeout=EXIT_S)
    assert not out.exists()
    assert staging_folder(out).is_dir()  # the torn bag, out of every reader's way
    rerun = _cli(*_import(log, out))
    assert rerun.returncode == 0, rerun.stderr
    assert f'removed {staging_folder(out)}' in rerun.stderr
    assert 'killed' in rerun.stderr
    assert (out / 'metadata.yaml').is_file()
    assert not staging_folder(out).exists()


def _write_and_fail(out: Path) -> None:
    with staged_bag(out) as staged:
        staged.mkdir()
        (staged / 'metadata.yaml').write_text('half a bag')
        raise ConfigError('broken')


def test_a_failed_writer_leaves_nothing_and_its_error_says_so(tmp_path: Path) -> None:
    out = tmp_path / 'bag'
    with pytest.raises(ConfigError, match=f'broken; nothing was written to {out}$'):
        _write_and_fail(out)
    assert list(tmp_path.iterdir()) == []


def test_a_staging_folder_holding_something_foreign_is_never_removed(tmp_path: Path) -> None:
    out = tmp_path / 'bag'
    foreign = staging_folder(out) / 'notes.txt'
    foreign.parent.mkdir()
    foreign.write_text('mine')
    with pytest.raises(OutputError, match=r'holds what no writer of .* put there; move it away'):
        _write_and_fail(out)
    assert foreign.read_text() == 'mine'
    assert not out.exists()
    assert not out.with_name(out.name + LOCK_SUFFIX).exists()


def test_a_simulation_interrupted_while_writing_leaves_no_bag(tmp_path: Path) -> None:
    from id_learning.twin import load_twin_config

    out = tmp_path / 'bag'
    config = str(REPO / 'config' / 'twin_default.yaml')
    argv = ['simulate', '--config', config, '--out', str(out), '--duration', '5', '--quiet']
    status, lines = _stop(_half_written(argv), signal.SIGINT)
    assert status == 130, lines
    assert not out.exists()  # before: a bag of 50 samples that looked complete
    assert list(tmp_path.iterdir()) == []
    rerun = _cli(*argv)
    assert rerun.returncode == 0, rerun.stderr
    # The copy of the twin config, written in the hidden folder, reads its robot from here.
    assert load_twin_config(out / 'twin_config.yaml').robot.n_joints == 6
