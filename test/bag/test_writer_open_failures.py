"""A bag that cannot even be started (a disk already full) is one line and leaves no empty file;
one bag has one writer at a time: a second is refused naming the first's pid, never told that the
bag in progress is torn."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading
from collections.abc import Callable

import pytest
from support import REPO

from id_learning.bag import JOINT_STATE, BagWriter
from id_learning.bag.recover import recover_bag
from id_learning.dataset.recording import write_recording
from id_learning.outputs import OutputError, bag_output, check_bag_output

#: Runs ``python ARGS`` with a file size limit (argv[1], bytes): a full disk, for real. CPython
#: ignores SIGXFSZ, so a write past it fails with EFBIG; exec keeps the limit.
LIMITED = (
    'import os, resource, sys; n = int(sys.argv[1]); '
    'resource.setrlimit(resource.RLIMIT_FSIZE, (n, n)); '
    'os.execv(sys.executable, [sys.executable, *sys.argv[2:]])'
)
#: Room for the lock's pid, not for an MCAP file's magic and header [bytes].
PID_ONLY_BYTES = 16

OPEN = textwrap.dedent(
    """
    import sys
    from id_learning.bag import BagWriter
    from id_learning.errors import IdLearningError

    try:
        BagWriter(sys.argv[1]).open()
    except IdLearningError as err:
        print(f'{type(err).__name__}: {err}')
    """
)


def _run(*argv: str, limit: int | None = None) -> subprocess.CompletedProcess[str]:
    limited = ['-c', LIMITED, str(limit)] if limit is not None else []
    return subprocess.run(
        [sys.executable, *limited, *argv],
        capture_output=True, text=True, cwd=REPO, timeout=120, check=False,
        env={**os.environ, 'PYTHONDONTWRITEBYTECODE': '1'},
    )  # fmt: skip


def _one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    said = done.stderr.strip()
    assert done.returncode == 2, said
    assert 'Traceback' not in said
    lines = [line for line in said.splitlines() if 'error' in line]
    assert len(lines) == 1, said
    return lines[0]


# -- a disk already full --------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('limit', 'said'),
    [(PID_ONLY_BYTES, 'BagError: {out}: writing failed: File too large (starting bag_0.mcap)'),
     (0, 'OutputError: {out}.lock: File too large (locking {out})')],
)  # fmt: skip
def test_a_bag_that_cannot_be_started_says_why_and_leaves_nothing(tmp_path, limit, said):
    out = tmp_path / 'bag'
    done = _run('-c', OPEN, str(out), limit=limit)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(said.format(out=out)), done.stdout
    assert list(tmp_path.iterdir()) == []  # neither the folder, nor an empty .mcap, nor the lock


def test_simulate_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path):
    out = tmp_path / 'bag'
    config = str(REPO / 'config/twin_default.yaml')
    done = _run('-m', 'id_learning.cli', 'simulate', '--config', config, '--duration', '26',
                '--out', str(out), '--quiet', limit=PID_ONLY_BYTES)  # fmt: skip
    line = _one_error_line(done)
    assert f'{out}: writing failed: File too large' in line
    assert list(tmp_path.iterdir()) == []


def test_a_plot_on_a_full_disk_is_one_line_and_leaves_nothing(short_twin, tmp_path):
    _, result = short_twin
    bag = write_recording(result.recording, tmp_path / 'bag')
    plots = tmp_path / 'plots'
    plots.mkdir()
    plot = plots / 'p.png'
    done = _run('-m', 'id_learning.cli', 'inspect', str(bag), '--plot', str(plot),
                limit=PID_ONLY_BYTES)  # fmt: skip
    line = _one_error_line(done)
    assert f'{plot}: File too large (writing the plot)' in line
    assert list(plots.iterdir()) == []  # no empty image, no temporary file


# -- one writer per bag ---------------------------------------------------------------------------
def _in_thread(call: Callable[[], object]) -> BaseException | None:
    """What ``call`` raised in another thread (another writer in this process), or None."""
    raised: list[BaseException] = []

    def run() -> None:
        try:
            call()
        except BaseException as err:  # handed to the test
            raised.append(err)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(timeout=60)
    return raised[0] if raised else None


def test_a_bag_being_written_is_refused_to_a_second_writer_naming_the_first(tmp_path):
    out = tmp_path / 'conc'
    holder = f'another process (pid {os.getpid()}) is writing it'
    with BagWriter(out) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        # What a second writer finds looks torn: an .mcap file without metadata.yaml.
        assert sorted(p.name for p in out.iterdir()) == ['conc_0.mcap']
        for call in (
            lambda: check_bag_output(out, overwrite=True),
            lambda: BagWriter(out, overwrite=True).open(),
            lambda: recover_bag(out),
        ):
            err = _in_thread(call)
            assert isinstance(err, OutputError), err
            assert holder in str(err)
            assert 'torn' not in str(err)
        done = _run('-c', OPEN, str(out))  # another process
        assert done.stdout.startswith(f'OutputError: {out}: {holder}'), done.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ['conc']  # the lock is gone with it
    assert sorted(p.name for p in out.iterdir()) == ['conc_0.mcap', 'metadata.yaml']


def test_a_command_holding_the_bag_lets_its_own_writer_in_and_refuses_simulate(tmp_path):
    out = tmp_path / 'deep' / 'bag'
    with bag_output(out) as folder:
        assert folder == out
        assert (tmp_path / 'deep' / 'bag.lock').read_text() == f'{os.getpid()}\n'
        config = str(REPO / 'config/twin_default.yaml')
        done = _run('-m', 'id_learning.cli', 'simulate', '--config', config, '--out', str(out),
                    '--quiet')  # fmt: skip
        line = _one_error_line(done)
        assert f'{out}: another process (pid {os.getpid()}) is writing it' in line
        assert not out.exists()
        with BagWriter(out) as writer:  # the command's own writer, under its lock
            writer.add_topic('/joint_states', JOINT_STATE)
        assert (tmp_path / 'deep' / 'bag.lock').exists()  # still the command's
    assert sorted(p.name for p in (tmp_path / 'deep').iterdir()) == ['bag']


def test_a_recovery_onto_a_full_disk_names_its_target_and_leaves_all_as_it_was(
    short_twin, tmp_path
):
    _, result = short_twin
    torn = write_recording(result.recording, tmp_path / 'torn')
    (torn / 'metadata.yaml').unlink()  # torn: its recorder never closed it
    before = sorted(p.name for p in torn.iterdir())
    out = tmp_path / 'out'
    done = _run('-m', 'id_learning.cli', 'bag', 'recover', str(torn), '--out', str(out),
                limit=PID_ONLY_BYTES)  # fmt: skip
    line = _one_error_line(done)
    assert f'{out}: the recovered bag could not be written (File too large)' in line
    assert '.recovering' not in line  # the hidden staging folder is gone: not named
    assert '(id-learning bag recover)' not in line  # the command that just failed
    assert sorted(p.name for p in torn.iterdir()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['torn']
