"""Running this package's nodes as child processes: the online check, benchmarks and tests use it.

A node runs as ``python -m id_learning.nodes.<module> --ros-args -r ... -p ...`` with the given
environment (the PyPI wheels' bootstrap needs the whole of it: LD_LIBRARY_PATH, AMENT_PREFIX_PATH)
and its stdout and stderr in a log file.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

__all__ = ['NodeProcess', 'ros_value']


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
        command = [sys.executable, '-m', f'id_learning.nodes.{module}', '--ros-args']
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
