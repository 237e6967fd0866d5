"""Result folders are written whole or not at all, by one writer, and never over what they must
not replace; an interrupted run is refused by every reader; a full disk is one clear line."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from support import REPO

from id_learning.cli.main import main
from id_learning.errors import CheckpointError
from id_learning.output_kinds import WRITTEN_ENTRIES
from id_learning.outputs import (
    INCOMPLETE_FILE,
    MANIFEST_FILE,
    OutputError,
    partial_path,
    result_folder,
)
from id_learning.training import evaluate_run, read_run, train_run
from id_learning.training.closed_loop_run import closed_loop_run

#: A file size limit below a report figure's size [bytes] (a full disk, for real).
FIGURE_LIMIT_BYTES = 20_000


@pytest.fixture(scope='module')
def small_run(bags, mabi, tmp_path_factory):
    """An RNEA+LQ run on the first bag (seconds to fit)."""
    out = tmp_path_factory.mktemp('small') / 'run'
    return train_run(bags[:1], mabi, 'motor', ['rnea_lq'], out, progress=False, device='cpu')


def _cli(capsys, *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.err + captured.out


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob('*') if p.is_file()}


def _refused(out: Path, match: str, **options) -> None:
    """Opening ``out`` raises OutputError matching ``match``."""
    with pytest.raises(OutputError, match=match), result_folder(out, command='test', **options):
        pass


def _fail_midway(out: Path, *, keep: bool) -> None:
    with result_folder(out, command='train') as folder:
        folder.keep = keep
        (folder.work / 'metrics.json').write_text('{}')
        raise RuntimeError('midway')


#: Runs ``python ARGS`` with a file size limit (argv[1], bytes): a full disk, for real. CPython
#: ignores SIGXFSZ, so a write past it fails with EFBIG; exec keeps the limit.
LIMITED = (
    'import os, resource, sys; n = int(sys.argv[1]); '
    'resource.setrlimit(resource.RLIMIT_FSIZE, (n, n)); '
    'os.execv(sys.executable, [sys.executable, *sys.argv[2:]])'
)


def _refused_on_a_full_disk(limit: int, *args: object) -> str:
    """An ``id-learning`` command run with files capped at ``limit`` bytes: its error output.

    It must fail with exit 2 and no traceback.
    """
    done = subprocess.run(
        [sys.executable, '-c', LIMITED, str(limit), '-m', 'id_learning.cli', *map(str, args),
         '--quiet'],
        capture_output=True, text=True, cwd=REPO, timeout=300,
        env={**os.environ, 'PYTHONDONTWRITEBYTECODE': '1'}, check=False,
    )  # fmt: skip
    said = done.stderr.strip()
    assert done.returncode == 2, said
    assert 'Traceback' not in said
    return said


# -- the folder itself ----------------------------------------------------------------------------
def test_a_result_is_written_beside_its_folder_and_renamed_there_when_complete(tmp_path):
    out = tmp_path / 'deep' / 'result'
    with result_folder(out, command='test') as folder:
        assert folder.work == partial_path(out)
        marker = json.loads((folder.work / INCOMPLETE_FILE).read_text())
        assert (marker['command'], marker['pid']) == ('test', os.getpid())
        assert not out.exists()
        assert (tmp_path / 'deep' / 'result.lock').exists()
        (folder.work / 'metrics.json').write_text('{}')
    assert sorted(p.name for p in (tmp_path / 'deep').iterdir()) == ['result']
    assert sorted(p.name for p in out.iterdir()) == ['.id_learning.json', 'metrics.json']


def test_a_failure_leaves_nothing_and_a_kept_partial_says_it_is_incomplete(tmp_path):
    out = tmp_path / 'result'
    with pytest.raises(RuntimeError, match='midway'):
        _fail_midway(out, keep=False)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError, match='midway'):
        _fail_midway(out, keep=True)
    assert not out.exists()
    assert (partial_path(out) / INCOMPLETE_FILE).is_file()
    # A new writer is refused without --force, naming the interrupted result, then replaces it.
    _refused(out, r'result\.partial: an incomplete result .*--force')
    with result_folder(out, command='train', force=True) as folder:
        (folder.work / 'run.json').write_text('{}')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['result']


def test_an_existing_result_is_replaced_only_with_force_and_then_whole(tmp_path):
    out = tmp_path / 'result'
    out.mkdir()
    (out / 'metrics.json').write_text('old')
    (out / 'old_figure.png').write_text('old')
    _refused(out, r'holds an evaluation already \(metrics\.json\).*--force')
    assert (out / 'metrics.json').read_text() == 'old'
    with result_folder(out, command='evaluate', force=True) as folder:
        (folder.work / 'metrics.json').write_text('new')
    assert _tree(out).keys() == {'metrics.json', '.id_learning.json'}  # nothing old is left
    assert (out / 'metrics.json').read_text() == 'new'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['result']


def test_what_is_not_a_result_or_is_an_input_is_never_replaced_even_with_force(tmp_path):
    mine = tmp_path / 'thesis'
    mine.mkdir()
    (mine / 'chapter1.tex').write_text('precious')
    _refused(mine, 'thesis: holds files that are not an id_learning', force=True)
    assert _tree(mine) == {'chapter1.tex': b'precious'}
    run = tmp_path / 'run'
    run.mkdir()
    (run / 'run.json').write_text('{}')
    for out in (run, tmp_path):
        _refused(out, 'an input of this command', force=True, inputs=[run])
    assert _tree(run) == {'run.json': b'{}'}


def test_a_dangling_link_a_file_or_a_read_only_folder_is_one_clear_error(tmp_path):
    link = tmp_path / 'link'
    link.symlink_to(tmp_path / 'gone')
    _refused(link, r'link: is a symbolic link to .*gone, which does not exist')
    afile = tmp_path / 'file'
    afile.write_text('x')
    _refused(afile, 'file: exists and is not a folder', force=True)
    assert afile.read_text() == 'x'
    if os.geteuid() == 0:
        pytest.skip('root writes into read-only folders: the permission case needs a user')
    locked = tmp_path / 'locked'
    locked.mkdir(mode=0o500)
    try:
        _refused(locked / 'out', 'Permission denied')
    finally:
        locked.chmod(0o700)


HOLDER = textwrap.dedent(
    """
    import sys
    from id_learning.outputs import result_folder

    with result_folder(sys.argv[1], command='train'):
        print('holding', flush=True)
        sys.stdin.readline()
    """
)


def test_a_second_writer_is_refused_at_once_naming_the_holder(tmp_path, bags, capsys):
    out = tmp_path / 'run'
    holder = subprocess.Popen(
        [sys.executable, '-c', HOLDER, str(out)], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True, cwd=REPO,
    )  # fmt: skip
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline() == 'holding\n'
        status, said = _cli(capsys, 'train', '--bag', str(bags[0]), '--models', 'rnea_lq',
                            '--out', str(out), '--quiet', '--force')  # fmt: skip
        assert status == 2
        assert f'another process (pid {holder.pid}) is writing it' in said
        assert str(out) in said
    finally:
        holder.communicate('\n', timeout=30)
    assert holder.returncode == 0
    assert out.is_dir()  # the holder's result, untouched by the refused writer


# -- runs and evaluations -------------------------------------------------------------------------
def test_evaluate_never_writes_over_a_run_or_an_evaluation_without_force(
    small_run, bags, tmp_path, capsys
):
    run = str(small_run.out)
    before = _tree(small_run.out)
    base = ['evaluate', '--run', run, '--bag', str(bags[1]), '--quiet', '--out']
    status, said = _cli(capsys, *base, run, '--force')
    assert status == 2
    assert 'is an input of this command' in said
    other = tmp_path / 'other_run'
    shutil.copytree(small_run.out, other)
    for force in ((), ('--force',)):  # a run is never replaced by an evaluation
        status, said = _cli(capsys, *base, str(other), *force)
        assert (status, 'holds a train run (run.json)' in said) == (2, True), said
    assert (other / 'run.json').exists()
    evaluation = tmp_path / 'evaluation'
    assert _cli(capsys, *base, str(evaluation))[0] == 0
    status, said = _cli(capsys, *base, str(evaluation))
    assert (status, 'holds an evaluation' in said) == (2, True), said
    assert _cli(capsys, *base, str(evaluation), '--force')[0] == 0  # an evaluation replaced
    assert json.loads((evaluation / 'metrics.json').read_text())['kind'] == 'evaluation'
    assert _tree(small_run.out) == before


def _mark_incomplete(run: Path, folder: Path) -> None:
    """A copy of ``run`` as a killed train leaves it: its partial folder, marker and all."""
    shutil.copytree(run, folder)
    (folder / 'metrics.json').unlink()
    document = json.loads((folder / 'run.json').read_text())
    document['status'] = 'incomplete'
    document['requested_kinds'] = ['rnea_lq', 'mlp']
    (folder / 'run.json').write_text(json.dumps(document))
    marker = {'command': 'train', 'pid': 999_999_999, 'host': 'elsewhere'}
    (folder / INCOMPLETE_FILE).write_text(json.dumps(marker))


def test_every_reader_refuses_an_interrupted_run_naming_it(small_run, bags, mabi, tmp_path):
    out = tmp_path / 'run'
    _mark_incomplete(small_run.out, partial_path(out))
    expected = r'run\.partial.*incomplete.*holds 1 of 2 model\(s\).*train with --force'
    for folder in (out, partial_path(out)):
        with pytest.raises(CheckpointError, match=expected):
            read_run(folder)
        with pytest.raises(CheckpointError, match=expected):
            evaluate_run(folder, bags[1:], mabi, tmp_path / 'eval', progress=False)
        with pytest.raises(CheckpointError, match=expected):
            closed_loop_run(folder, mabi, tmp_path / 'loop', progress=False)
    with pytest.raises(CheckpointError, match=r'does not exist; only .*run\.partial does'):
        read_run(out)
    assert not (tmp_path / 'eval').exists()
    assert not (tmp_path / 'loop').exists()
    # A run.json that says incomplete, whatever the folder is called.
    renamed = tmp_path / 'renamed'
    shutil.copytree(partial_path(out), renamed)
    (renamed / INCOMPLETE_FILE).unlink()
    with pytest.raises(CheckpointError, match=r'renamed: an incomplete training run \(run\.json'):
        read_run(renamed)


def test_the_online_check_refuses_a_model_of_an_interrupted_run(small_run, tmp_path, bags):
    pytest.importorskip('rclpy', reason='the online check needs rclpy (ROS 2 Jazzy)')
    from id_learning.online_check import online_check

    folder = partial_path(tmp_path / 'run')
    _mark_incomplete(small_run.out, folder)
    with pytest.raises(CheckpointError, match='incomplete'):
        online_check(bags[0], REPO / 'config/mabi_max100.yaml', folder / 'models' / 'rnea_lq')


def _readline(stream, process: subprocess.Popen, text: str) -> list[str]:
    """Lines of ``stream`` up to the first holding ``text`` (the process prints as it goes)."""
    lines = []
    for line in stream:
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f'{text!r} never came (exit {process.wait()}): {"".join(lines)}')


def test_a_killed_train_leaves_a_partial_run_that_is_refused_until_replaced(
    bags, tmp_path, capsys
):
    out = tmp_path / 'run'
    train = [sys.executable, '-m', 'id_learning.cli', 'train', '--bag', str(bags[0]), '--out',
             str(out), '--quiet', '--device', 'cpu']  # fmt: skip
    # RNEA+LQ is fitted first and saved at once; the MLP would take minutes.
    process = subprocess.Popen(
        [*train, '--models', 'rnea_lq,mlp', '--hyper', 'mlp.max_epochs=100000'],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=REPO,
    )  # fmt: skip
    try:
        _readline(process.stderr, process, 'rnea_lq: fitted')
        assert (partial_path(out) / 'models' / 'rnea_lq' / 'model.json').is_file()
    finally:
        process.kill()
        process.communicate(timeout=30)
    assert not out.exists()
    assert (partial_path(out) / INCOMPLETE_FILE).is_file()
    status, said = _cli(capsys, 'evaluate', '--run', str(out), '--bag', str(bags[1]), '--out',
                        str(tmp_path / 'eval'), '--quiet')  # fmt: skip
    assert status == 2
    assert 'holds 1 of 2 model(s)' in said
    assert 'interrupted' in said
    status, said = _cli(capsys, *train[3:], '--models', 'rnea_lq')
    assert (status, '--force' in said, 'run.partial' in said) == (2, True, True), said
    assert _cli(capsys, *train[3:], '--models', 'rnea_lq', '--force')[0] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run']
    assert read_run(out)['status'] == 'complete'


def test_a_full_disk_while_writing_a_figure_is_one_line_and_leaves_nothing(
    small_run, bags, tmp_path
):
    out = tmp_path / 'eval'
    said = _refused_on_a_full_disk(
        FIGURE_LIMIT_BYTES, 'evaluate', '--run', small_run.out, '--bag', bags[1], '--out', out
    )
    lines = [line for line in said.splitlines() if 'error' in line]
    assert len(lines) == 1, said
    assert 'File too large' in lines[0]
    assert str(out) in lines[0]
    assert list(tmp_path.iterdir()) == []  # neither the result nor its partial folder


def test_every_entry_a_real_result_lists_is_one_a_partial_may_hold(small_run):
    listed = json.loads((small_run.out / MANIFEST_FILE).read_text())['entries']
    assert set(listed) <= WRITTEN_ENTRIES, set(listed) - WRITTEN_ENTRIES


def test_a_full_disk_while_simulating_says_nothing_was_kept(tmp_path):
    """The staged bag is removed: no 'kept' messages, no bag recover hint, nothing left."""
    out = tmp_path / 'twin'
    config = REPO / 'config' / 'twin_default.yaml'
    said = _refused_on_a_full_disk(
        2**20, 'simulate', '--config', config, '--out', out, '--duration', 300
    )
    assert f'{out}: writing failed: File too large; nothing was written to {out}' in said
    assert 'kept' not in said
    assert 'recover' not in said
    assert list(tmp_path.iterdir()) == []
