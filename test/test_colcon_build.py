"""The package builds with colcon, and its installed executables (what `ros2 run` runs) work."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

COLCON = Path(sys.executable).parent / 'colcon'


def tracked_files() -> list[str]:
    result = subprocess.run(['git', 'ls-files', '-z'], cwd=REPO, capture_output=True, check=False)
    if result.returncode != 0:  # not a git checkout (e.g. an unpacked release): take the tree
        return [
            str(p.relative_to(REPO))
            for p in REPO.rglob('*')
            if p.is_file() and '.venv' not in p.parts
        ]
    return [name for name in result.stdout.decode().split('\0') if name]


@pytest.fixture(scope='module')
def workspace(tmp_path_factory) -> Path:
    if not COLCON.exists():
        pytest.skip(f'colcon is not installed next to {sys.executable} (make test installs it)')
    ws = tmp_path_factory.mktemp('ws')
    package = ws / 'src' / 'id_learning'
    for name in tracked_files():
        target = package / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / name, target)
    env = {**os.environ, 'AMENT_PREFIX_PATH': os.environ.get('AMENT_PREFIX_PATH', sys.prefix)}
    result = subprocess.run(
        [str(COLCON), 'build', '--base-paths', 'src'],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return ws


def run_installed(ws: Path, command: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run a shell command with the workspace's install/setup.bash sourced, as a ROS user would."""
    script = f'source {ws}/install/setup.bash && {command}'
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


def test_every_installed_executable_runs_and_does_its_job(workspace, tmp_path):
    lib = workspace / 'install/id_learning/lib/id_learning'
    executables = sorted(p.name for p in lib.iterdir())
    assert 'id-learning' in executables
    for name in executables:
        result = run_installed(workspace, f'{lib / name} --help', tmp_path)
        assert result.returncode == 0, f'{name}: {result.stderr}'
    # The offline tool works from the install alone, outside the checkout.
    share = workspace / 'install/id_learning/share/id_learning'
    result = run_installed(
        workspace,
        f'{lib}/id-learning simulate --config {share}/config/twin_default.yaml'
        ' --out bag --duration 30 --quiet'
        f' && {lib}/id-learning inspect bag'
        f' && {lib}/id-learning demo --bag bag --out demo --skip-training',
        tmp_path,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert (tmp_path / 'demo/summary.md').is_file()
    imported = run_installed(
        workspace, 'python3 -c "import id_learning, sys; print(id_learning.__file__)"', tmp_path
    )
    assert str(workspace / 'install') in imported.stdout
