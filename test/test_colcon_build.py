"""The package builds with colcon, and its installed executables (what `ros2 run` runs) work."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support import REPO, ground_truth, inspect_topic_rows

pytestmark = pytest.mark.slow  # a colcon build, then the installed tools at work

COLCON = Path(sys.executable).parent / 'colcon'


def tracked_files() -> list[str]:
    """The working tree's files as a commit of it would hold them (new files not yet added too)."""
    result = subprocess.run(
        ['git', 'ls-files', '-z', '--cached', '--others', '--exclude-standard'],
        cwd=REPO,
        capture_output=True,
        check=False,
    )
    if result.returncode != 0:  # not a git checkout (e.g. an unpacked release): take the tree
        return [
            str(p.relative_to(REPO))
            for p in REPO.rglob('*')
            if p.is_file() and '.venv' not in p.parts
        ]
    names = {name for name in result.stdout.decode().split('\0') if name}
    return sorted(name for name in names if (REPO / name).is_file())  # not the deleted ones


def has_space(path: Path | str) -> bool:
    return any(character.isspace() for character in str(path))


def python_without_spaces(ws: Path) -> Path:
    """This venv's python by a path without whitespace, for colcon to build with.

    A workspace built by a python under a folder with a space does not run: colcon-bash's
    local_setup.bash calls the interpreter unquoted, and setuptools writes the executables'
    shebang quoted, which Linux does not read. A link to the venv's folder keeps it the same
    venv (python finds pyvenv.cfg beside the link's bin/).
    """
    if not has_space(sys.prefix):
        return Path(sys.executable)
    link = ws / 'venv'
    link.symlink_to(sys.prefix, target_is_directory=True)
    return link / 'bin' / Path(sys.executable).name


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    if not COLCON.exists():
        pytest.skip(f'colcon is not installed next to {sys.executable} (make test installs it)')
    ws = tmp_path_factory.mktemp('ws')
    if has_space(ws):
        pytest.skip(f'colcon cannot make a workspace that runs under {ws} (a space in the path)')
    package = ws / 'src' / 'id_learning'
    for name in tracked_files():
        target = package / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / name, target)
    env = {**os.environ, 'AMENT_PREFIX_PATH': os.environ.get('AMENT_PREFIX_PATH', sys.prefix)}
    result = subprocess.run(
        [str(python_without_spaces(ws)), str(COLCON), 'build', '--base-paths', 'src'],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return ws


def q(path: Path) -> str:
    """``path`` as one shell word."""
    return shlex.quote(str(path))


def run_installed(ws: Path, command: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run a shell command with the workspace's install/setup.bash sourced, as a ROS user would."""
    script = f'source {q(ws / "install/setup.bash")} && {command}'
    return subprocess.run(
        ['bash', '-c', script],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        env={**os.environ, 'PYTHONPATH': ''},
    )


def test_colcon_build_registers_the_package_in_the_ament_index(workspace):
    install = workspace / 'install' / 'id_learning'
    assert (install / 'share/ament_index/resource_index/packages/id_learning').is_file()
    assert (install / 'share/id_learning/package.xml').is_file()
    assert (install / 'share/id_learning/config/mabi_max100.yaml').is_file()


@pytest.fixture(scope='module')
def installed(workspace, tmp_path_factory) -> tuple[Path, Path, Path]:
    """The installed executables and share folders, and a folder outside the checkout that
    holds a 26 s twin bag ``bag`` the installed ``id-learning simulate`` wrote."""
    lib = workspace / 'install/id_learning/lib/id_learning'
    share = workspace / 'install/id_learning/share/id_learning'
    folder = tmp_path_factory.mktemp('installed')
    result = run_installed(
        workspace,
        f'{q(lib / "id-learning")} simulate --config {q(share / "config/twin_default.yaml")}'
        ' --out bag --duration 30 --seed 4 --quiet',
        folder,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return lib, share, folder


def test_the_installed_id_learning_inspects_and_trains_from_the_install_alone(
    workspace, installed
):
    lib, share, folder = installed
    truth, stamps = ground_truth(folder / 'bag')
    assert truth['seed'] == 4
    # As ``ros2 run`` starts them, outside the checkout; train gets the --ros-args block it adds.
    result = run_installed(
        workspace,
        f'{q(lib / "id-learning")} inspect bag'
        f' && {q(lib / "train")} --bag bag --models rnea_lq --out run --quiet'
        ' --ros-args -r __node:=train --',
        folder,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    rows = inspect_topic_rows(result.stdout)
    assert set(rows) == {'/joint_states', '/motor_currents'}
    for cells in rows.values():
        assert int(cells[1]) == len(stamps)
        assert float(cells[3]) == pytest.approx(1.0 / truth['ipo_period_s'], abs=5e-4)
    # The run used the installed robot config and scored the last 30 % of the recording.
    run = json.loads((folder / 'run/run.json').read_text())
    assert run['robot_config'] == str(share / 'config/mabi_max100.yaml')
    assert run['kinds'] == ['rnea_lq']
    metrics = json.loads((folder / 'run/metrics.json').read_text())
    assert metrics['n_samples'] == pytest.approx(0.3 * len(stamps), abs=1)
    assert len(metrics['models']['rnea_lq']['rmse_nm']) == len(truth['joints'])
    model = json.loads((folder / 'run/models/rnea_lq/model.json').read_text())
    assert model['kind'] == 'rnea_lq'
    imported = run_installed(
        workspace, 'python3 -c "import id_learning, sys; print(id_learning.__file__)"', folder
    )
    assert str(workspace / 'install') in imported.stdout


def test_the_installed_nodes_replay_a_bag_and_refuse_bad_parameters(workspace, installed):
    lib, _, folder = installed
    assert sorted(p.name for p in lib.iterdir()) == [
        'id-learning', 'predictor', 'recorder', 'replay', 'train'
    ]  # fmt: skip
    # Half a second of the bag: the cycles whose stamps lie within it, two topics each.
    _, stamps = ground_truth(folder / 'bag')
    cycles = int(np.sum(stamps - stamps[0] < 500_000_000))
    replay = run_installed(
        workspace,
        f'{q(lib / "replay")} --ros-args -p bag:=bag -p duration_s:=0.5'
        ' -p wait_for_subscribers:=0',
        folder,
    )
    assert replay.returncode == 0, replay.stderr
    log = replay.stdout + replay.stderr
    assert f'loaded {cycles} cycles ({2 * cycles} messages, 0.50 s)' in log
    assert f'published {cycles} cycles' in log
    (folder / 'no_artifact').mkdir(exist_ok=True)
    refusals = {
        'predictor': ('artifact:=no_artifact', 'no_artifact: not a model artifact'),
        'recorder': ('output:=bag', 'bag: holds a bag already'),
    }
    for node, (parameter, message) in refusals.items():
        result = run_installed(workspace, f'{q(lib / node)} --ros-args -p {parameter}', folder)
        assert result.returncode == 2, f'{node}: {result.stderr}'
        assert message in result.stderr, node
