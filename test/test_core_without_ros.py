"""The core library imports and works where ROS is absent."""

from __future__ import annotations

import subprocess
import sys

from support import REPO

CORE_MODULES = [
    path.relative_to(REPO).with_suffix('').as_posix().replace('/', '.')
    for path in sorted((REPO / 'id_learning').rglob('*.py'))
    if 'nodes' not in path.parts and path.name != '__main__.py'
]


def test_every_core_module_imports_with_rclpy_blocked():
    assert len(CORE_MODULES) > 15
    code = (
        'import sys, importlib\n'
        "for name in ('rclpy', 'rclpy.node', 'sensor_msgs', 'sensor_msgs.msg', 'std_msgs'):\n"
        '    sys.modules[name] = None\n'
        f'for module in {CORE_MODULES!r}:\n'
        '    importlib.import_module(module)\n'
        "print('ok')\n"
    )
    result = subprocess.run(
        [sys.executable, '-c', code],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == 'ok'
