"""The command line on a closed pipe, with paths the file system cannot hold, naming its options.

Run as a user runs it: real processes for the pipe, real bags and folders.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest
from support import REPO, sine_recording, twin_config

from id_learning.cli.main import main
from id_learning.dataset.recording import write_recording
from id_learning.output_kinds import NAME_RESERVE

#: 128 + SIGPIPE: what a shell reports for a program a closed pipe ended.
CLOSED_PIPE_STATUS = 141


@pytest.fixture(scope='module')
def small_bag(tmp_path_factory):
    return write_recording(sine_recording(400), tmp_path_factory.mktemp('robust') / 'bag')


def _into_closed_pipe(*argv: str) -> subprocess.CompletedProcess[str]:
    """Run ``argv`` (after python) with a standard output whose reader is already gone."""
    read, write = os.pipe()
    os.close(read)  # as `| head -1` once it has its line: every write fails with EPIPE
    try:
        return subprocess.run(
            [sys.executable, *argv],
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            cwd=REPO,
            timeout=300,
            check=False,
        )
    finally:
        os.close(write)


# -- a closed standard output -----------------------------------------------------------------
@pytest.mark.parametrize(
    'argv',
    [
        ['-m', 'id_learning.cli', 'inspect', '{bag}'],
        ['-m', 'id_learning.cli', '--help'],
        ['-m', 'id_learning.cli', 'demo', '--help'],
    ],
    ids=['inspect', 'help', 'demo-help'],
)
def test_a_command_whose_output_is_closed_exits_quietly(argv, small_bag):
    result = _into_closed_pipe(*(item.format(bag=small_bag) for item in argv))
    assert result.returncode in (0, CLOSED_PIPE_STATUS), result.stderr
    assert result.stderr == '', result.stderr  # no traceback, no 'Exception ignored'
    if 'inspect' in argv:
        assert result.returncode == CLOSED_PIPE_STATUS  # its report was cut short


def test_a_node_help_into_a_closed_pipe_exits_quietly():
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    result = _into_closed_pipe('-m', 'id_learning.nodes.recorder', '--help')
    assert result.returncode == CLOSED_PIPE_STATUS, result.stderr
    assert 'Traceback' not in result.stderr
    assert 'BrokenPipe' not in result.stderr


# -- names the file system cannot hold ------------------------------------------------------------
def _long(tmp_path, size: int = 300):
    return tmp_path / ('x' * size)


@pytest.mark.parametrize(
    ('command', 'option'),
    [
        (['demo', '--models', 'rnea_lq', '--out', '{out}'], '--out'),
        (['train', '--bag', '{bag}', '--models', 'rnea_lq', '--quiet', '--out', '{out}'], '--out'),
        (['simulate', '--config', str(REPO / 'config/twin_default.yaml'), '--out', '{out}'],
         '--out'),
        (['inspect', '{bag}', '--plot', '{out}.png'], '--plot'),
        (['bag', 'recover', '{bag}', '--out', '{out}'], 'path'),  # the net in cli.main
    ],
    ids=['demo', 'train', 'simulate', 'inspect', 'recover'],
)  # fmt: skip
def test_an_output_name_too_long_is_one_line_naming_it_and_the_option(
    command, option, small_bag, tmp_path, capsys
):
    out = _long(tmp_path)
    argv = [item.format(bag=small_bag, out=out) for item in command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err
    assert err.startswith(f'id-learning {command[0]}: error: {out}'), err
    assert 'file name too long' in err.lower()
    assert f'choose a shorter {option}' in err
    assert sorted(tmp_path.iterdir()) == []  # nothing created, not even a lock


def test_an_output_name_at_the_limit_is_written_and_one_byte_more_refused(tmp_path, capsys):
    limit = os.pathconf(tmp_path, 'PC_NAME_MAX') - NAME_RESERVE
    fits, too_long = _long(tmp_path, limit), _long(tmp_path, limit + 1)
    config = str(REPO / 'config/twin_default.yaml')
    simulate = ['simulate', '--config', config, '--duration', '1', '--quiet', '--out']
    assert main([*simulate, str(fits)]) == 0
    assert main([*simulate, str(fits), '--force']) == 0  # replaced: its lock beside it, again
    assert (fits / 'metadata.yaml').is_file()
    assert main([*simulate, str(too_long)]) == 2
    assert f'{limit + 1} bytes, at most {limit}' in capsys.readouterr().err
    assert sorted(tmp_path.iterdir()) == [fits]


# -- messages name the option the user set ------------------------------------------------------
def test_inspect_names_plot_when_the_plot_would_go_into_the_bag(small_bag, capsys):
    before = sorted(path.name for path in small_bag.iterdir())
    assert main(['inspect', str(small_bag), '--plot', str(small_bag / 'overview.png')]) == 2
    err = capsys.readouterr().err
    assert 'an input of this command' in err
    assert 'choose another --plot' in err
    assert '--out' not in err
    assert sorted(path.name for path in small_bag.iterdir()) == before


# -- the demo's closed loop on a real robot's bag -------------------------------------------------
def test_demo_refuses_a_twin_it_cannot_use_before_any_work(small_bag, tmp_path, capsys):
    missing = tmp_path / 'missing.yaml'
    argv = ['demo', '--bag', str(small_bag), '--out', str(tmp_path / 'demo')]
    assert main([*argv, '--twin', str(missing)]) == 2
    assert f'--twin {missing}' in capsys.readouterr().err
    assert main([*argv, '--twin', str(missing), '--closed-loop-seconds', '0']) == 2
    assert '--twin means nothing with --closed-loop-seconds' in capsys.readouterr().err
    assert main([*argv, '--twin', str(missing), '--skip-training']) == 2
    assert '--twin means nothing with --skip-training' in capsys.readouterr().err
    assert not (tmp_path / 'demo').exists()


@pytest.mark.slow  # a simulation, a training run with its report, a closed loop
def test_demo_runs_the_closed_loop_of_a_bag_without_twin_config_given_twin(tmp_path, capsys):
    from id_learning.twin import simulate, write_twin_output
    from id_learning.twin.simulate import TWIN_CONFIG_COPY

    config = twin_config(30.0, seed=5)
    simulated = write_twin_output(simulate(config), config, tmp_path / 'twin')
    real = shutil.copytree(simulated, tmp_path / 'real', ignore=shutil.ignore_patterns(
        TWIN_CONFIG_COPY))  # fmt: skip
    # Without --twin the demo says 'closed loop not run: no twin_config.yaml beside ...; pass
    # --twin CONFIG' (closed_loop_run's words): the demo takes that option.
    argv = ['demo', '--bag', str(real), '--models', 'rnea_lq', '--skip-diagnosis',
            '--online-seconds', '0', '--closed-loop-seconds', '1', '--out', str(tmp_path / 'd'),
            '--twin', str(simulated / TWIN_CONFIG_COPY)]  # fmt: skip
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert 'closed loop not run' not in said
    assert 'RMS tracking error' in said
    assert (tmp_path / 'd' / 'closed_loop' / 'closed_loop.json').is_file()


@pytest.mark.parametrize(
    ('argv', 'named'),
    [
        (['train', '--bag', 'BAG', '--out', ''], '--out'),
        (['train', '--bag', '', '--bag', 'BAG', '--out', 'OUT'], '--bag'),
        (['train', '--bag', 'BAG', '--out=', '--robot', 'ROBOT'], '--out'),
        (['evaluate', '--run', ' ', '--bag', 'BAG', '--out', 'OUT'], '--run'),
        (['inspect', ''], 'bag'),
        (['simulate', '--config', '', '--out', 'OUT'], '--config'),
        (['diagnose', '--bag', 'BAG', '--out', 'OUT', '--robot', ''], '--robot'),
    ],
)
def test_an_empty_path_is_refused_naming_it_before_any_work(
    argv, named, small_bag, tmp_path, capsys, monkeypatch
):
    """Path('') is the working folder: never what an empty --out or --bag meant."""
    monkeypatch.chdir(tmp_path)
    robot = REPO / 'config' / 'mabi_max100.yaml'
    real = {'BAG': str(small_bag), 'OUT': str(tmp_path / 'out'), 'ROBOT': str(robot)}
    argv = [real.get(item, item) for item in argv]

    with pytest.raises(SystemExit) as exited:
        main(argv)

    assert exited.value.code == 2
    assert f'error: {named}: an empty path; name the file or folder' in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    'argv',
    [
        ['train', '--bag', 'b', '--out', 'o', '--max-seconds-per-model', '1e-9'],
        ['demo', '--bag', 'b', '--out', 'o', '--train-seconds', '1e-9'],
        ['sweep', '--bag', 'b', '--out', 'o', '--kind', 'mlp', '--max-seconds-per-trial', '1e-9'],
    ],
)
def test_a_fit_budget_below_what_a_fit_takes_names_the_option_given(argv, capsys):
    """The option's own range is the fit's: not refused later as a hyper-parameter."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    said = capsys.readouterr().err
    assert f'argument {argv[-2]}: must be a finite number in [0.001, 10000000], got 1e-9' in said


# -- an address-space limit (probe 16, C26/C27) -------------------------------------------------
def _limited(limit_bytes: int) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))


def test_a_memory_limit_is_one_line_naming_it_and_nothing_is_left(tmp_path):
    # Under ulimit -v, numpy's allocation of a long excitation failed with a traceback.
    out = tmp_path / 'sim'
    done = subprocess.run(
        [sys.executable, '-m', 'id_learning.cli', 'simulate', '--config',
         str(REPO / 'config/twin_default.yaml'), '--out', str(out), '--duration', '20000',
         '--quiet'],
        capture_output=True, text=True, cwd=tmp_path, timeout=300, check=False,
        preexec_fn=lambda: _limited(2_500 * 2**20),
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith('id-learning simulate: error: out of memory (')
    assert 'of address space (ulimit -v): raise it' in lines[0]
    assert 'Traceback' not in done.stderr
    assert not out.exists()


def test_a_deleted_working_folder_is_one_line_naming_it(tmp_path):
    # Probe 16 (C58): train from a deleted folder ended in MKL's 'Cannot load libtorch_cpu.so'.
    gone = tmp_path / 'gone'
    gone.mkdir()
    done = subprocess.run(
        [sys.executable, '-m', 'id_learning.entry', 'id-learning', '--version'],
        capture_output=True, text=True, cwd=gone, timeout=120, check=False,
        preexec_fn=lambda: os.rmdir(gone), env={**os.environ, 'PYTHONPATH': str(REPO)},
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        'id-learning: error: the working folder no longer exists (deleted after the shell '
        'entered it); cd into an existing folder'
    )
