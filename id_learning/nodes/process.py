"""Running this package's nodes as child processes: the online check, benchmarks and tests use it.

A node runs as ``python -m id_learning.entry <module> --ros-args -r ... -p ...`` (as its console
script does: Ctrl-C while it imports is one line) with the given environment (the PyPI wheels'
bootstrap needs the whole of it: LD_LIBRARY_PATH, AMENT_PREFIX_PATH) and its stdout and stderr
in a log file. ``node_processes`` starts nodes in one DDS domain and
stops every one of them on exit.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import id_learning

__all__ = ['NodeProcess', 'StartNode', 'node_environment', 'node_processes', 'ros_value']


def ros_value(value: Any) -> str:
    """A parameter value as ``-p name:=value`` text (YAML): booleans lower case, lists quoted."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(f"'{item}'" for item in value) + ']'
    return str(value)


class NodeProcess:
    """One node of this package in a child process, its output going to ``log_path``."""

    def __init__(
        self,
        module: str,
        parameters: dict[str, Any],
        log_path: Path,
        env: dict[str, str],
        remaps: dict[str, str] | None = None,
    ) -> None:
        """Start the node now."""
        command = [sys.executable, '-m', 'id_learning.entry', module, '--ros-args']
        for old, new in (remaps or {}).items():
            command += ['-r', f'{old}:={new}']
        for name, value in parameters.items():
            command += ['-p', f'{name}:={ros_value(value)}']
        self.module = module
        self.log_path = log_path
        self._log = log_path.open('wb')
        self.process = subprocess.Popen(
            command, env=env, stdout=self._log, stderr=subprocess.STDOUT, cwd=log_path.parent
        )
        self.was_killed = False

    @property
    def is_running(self) -> bool:
        """Whether the process has not ended yet."""
        return self.process.poll() is None

    def log(self) -> str:
        """Everything the node printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors='replace')

    def interrupt(self) -> None:
        """Send SIGINT without waiting."""
        if self.is_running:
            self.process.send_signal(signal.SIGINT)

    def stop(self, timeout: float = 20.0) -> int | None:
        """SIGINT, wait up to ``timeout`` seconds, then SIGKILL; returns the exit status."""
        if self.is_running:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
        self._log.close()
        return self.process.returncode

    def kill(self) -> None:
        """SIGKILL now (a killed node leaves Fast DDS shared-memory files behind)."""
        if self.is_running:
            self.process.kill()
            self.was_killed = True
        self.process.wait(10)

    def wait(self, timeout: float) -> int:
        """Wait for the process to end by itself."""
        return self.process.wait(timeout)


#: ``start(module, parameters, remaps)``: start a node process.
StartNode = Callable[[str, dict[str, object], dict[str, str]], NodeProcess]
#: Deadline for a node to exit after SIGINT before it is killed [s].
STOP_S = 15.0


def node_environment(domain_id: int) -> dict[str, str]:
    """The whole environment (the wheels' bootstrap needs LD_LIBRARY_PATH) in our domain."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    env['PYTHONUNBUFFERED'] = '1'
    # The children import this very package, whatever their working directory.
    package_root = str(Path(id_learning.__file__).resolve().parents[1])
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [package_root, env.get('PYTHONPATH')]))
    return env


@contextmanager
def node_processes(log_dir: Path, domain_id: int) -> Iterator[StartNode]:
    """Start nodes with ``start(module, parameters, remaps)``, their logs in ``log_dir``.

    Every node started is stopped on exit, also on an error or Ctrl-C.
    """
    started: list[NodeProcess] = []
    env = node_environment(domain_id)

    def start(module: str, parameters: dict[str, object], remaps: dict[str, str]) -> NodeProcess:
        node = NodeProcess(module, parameters, log_dir / f'{module}.log', env, remaps)
        started.append(node)
        return node

    try:
        yield start
    finally:
        for node in started:  # all at once: each needs a moment to close
            node.interrupt()
        for node in started:
            node.stop(STOP_S)
        if any(node.was_killed for node in started):
            # A killed node leaves Fast DDS shared-memory files behind.
            fastdds = shutil.which('fastdds') or str(Path(sys.executable).parent / 'fastdds')
            if Path(fastdds).exists():
                subprocess.run(
                    [fastdds, 'shm', 'clean'], capture_output=True, timeout=60, check=False
                )
