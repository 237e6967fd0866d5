"""A bag is written only where a bag (or nothing) is: never over another command's result, a
file, an input; inspect's --plot is checked before the bag is read; the recorder refuses at start.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from id_learning.bag import BagWriter
from id_learning.cli.main import main
from id_learning.dataset.recording import write_recording
from id_learning.outputs import OutputError


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob('*') if p.is_file()}


def _cli(capsys, *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.err + captured.out


@pytest.fixture
def run(tmp_path) -> Path:
    """A folder that looks like a train run."""
    folder = tmp_path / 'run'
    folder.mkdir()
    (folder / 'run.json').write_text('{}')
    (folder / 'metrics.json').write_text('{}')
    return folder


@pytest.fixture(scope='module')
def bag(short_twin, tmp_path_factory) -> Path:
    _, result = short_twin
    return write_recording(result.recording, tmp_path_factory.mktemp('bag') / 'bag')


def test_the_writer_replaces_a_bag_but_never_a_run(tmp_path, run, bag):
    before = _tree(run)
    with pytest.raises(OutputError, match=r'holds a train run \(run\.json\); --force replaces'):
        BagWriter(run, overwrite=True).open()
    assert _tree(run) == before
    copy = tmp_path / 'copy'
    copy.mkdir()
    for file in bag.iterdir():
        (copy / file.name).write_bytes(file.read_bytes())
    with BagWriter(copy, overwrite=True) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
    assert sorted(p.name for p in copy.iterdir()) == ['copy_0.mcap', 'metadata.yaml']


def test_import_into_the_folder_of_its_inputs_is_refused(tmp_path, capsys, run):
    logs = tmp_path / 'logs'
    logs.mkdir()
    (logs / 'log.csv').write_text('t,q\n0,0\n')
    (logs / 'm.yaml').write_text('joints: []\n')
    before = _tree(logs)
    argv = ['import', str(logs / 'log.csv'), '--mapping', str(logs / 'm.yaml'), '--force']
    status, said = _cli(capsys, *argv, '--out', str(logs))
    assert (status, 'an input of this command' in said) == (2, True), said
    assert _tree(logs) == before
    status, said = _cli(capsys, *argv, '--out', str(run))
    assert (status, 'replaces only a bag' in said) == (2, True), said
    afile = tmp_path / 'afile'
    afile.write_text('mine')
    status, said = _cli(capsys, *argv, '--out', str(afile))
    assert (status, 'not a folder but a file' in said, 'Traceback' in said) == (2, True, False)


def test_inspect_plot_is_checked_before_the_bag_is_read(tmp_path, capsys, run, bag):
    missing = str(tmp_path / 'no_bag')  # never read: the plot path is refused first
    cases = (
        (run / 'metrics.json', 'not a file type'),
        (tmp_path, 'is a folder'),
        (Path('/proc/x.png'), 'cannot write in /proc'),
        (run / 'plot.png', 'holds a train run'),
    )
    for path, words in cases:
        status, said = _cli(capsys, 'inspect', missing, '--plot', str(path), '--force')
        assert (status, words in said, 'Traceback' in said) == (2, True, False), said
    assert (run / 'metrics.json').read_text() == '{}'
    plot = tmp_path / 'overview.svg'
    assert _cli(capsys, 'inspect', str(bag), '--plot', str(plot))[0] == 0
    assert plot.read_bytes().lstrip().startswith(b'<?xml')
    status, said = _cli(capsys, 'inspect', str(bag), '--plot', str(plot))
    assert (status, 'exists' in said and '--force' in said) == (2, True), said
    assert _cli(capsys, 'inspect', str(bag), '--plot', str(plot), '--force')[0] == 0


@pytest.mark.ros
def test_the_recorder_refuses_a_run_or_a_file_at_start(tmp_path, run):
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    from ros.ros_helpers import node_environment, random_domain

    before = _tree(run)
    afile = tmp_path / 'afile'
    afile.write_text('mine')
    env = node_environment(random_domain())
    env['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')
    cases = (
        (run, 'holds a train run (run.json); overwrite:=true replaces only a bag'),
        (afile, 'not a folder but a file'),
        (Path('/proc/x'), 'cannot write in /proc'),
    )
    for output, words in cases:
        done = subprocess.run(
            [sys.executable, '-m', 'id_learning.nodes.recorder', '--ros-args', '-p',
             f'output:={output}', '-p', 'overwrite:=true'],
            check=False, env=env, capture_output=True, text=True, timeout=120, cwd=tmp_path,
        )  # fmt: skip
        said = done.stdout + done.stderr
        assert (done.returncode, words in said, 'Traceback' in said) == (2, True, False), said
    assert _tree(run) == before
    assert afile.read_text() == 'mine'


def test_overwrite_never_deletes_a_file_the_metadata_does_not_list(tmp_path, bag):
    copy = tmp_path / 'copy'
    copy.mkdir()
    for file in bag.iterdir():
        (copy / file.name).write_bytes(file.read_bytes())
    (copy / 'extra.mcap').write_text('mine')  # an .mcap file, but not the bag's
    with pytest.raises(OutputError, match=r'extra\.mcap, which its metadata\.yaml does not'):
        BagWriter(copy, overwrite=True).open()
    assert (copy / 'extra.mcap').read_text() == 'mine'
