"""What every benchmark records beside its numbers: machine, torch threads, git commit, load."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import torch

REPO = Path(__file__).resolve().parents[1]
DEFAULT_BAG = REPO / 'bags' / 'default'
DEFAULT_ROBOT = REPO / 'config' / 'mabi_max100.yaml'


def git_commit() -> str | None:
    try:
        result = subprocess.run(
            ['git', 'rev-parse', 'HEAD'], capture_output=True, text=True, cwd=REPO, check=False
        )
    except OSError:
        return None
    dirty = subprocess.run(
        ['git', 'status', '--porcelain', '--untracked-files=no'],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=False,
    ).stdout.strip()
    commit = result.stdout.strip() or None
    return f'{commit}+dirty' if commit and dirty else commit


def environment() -> dict[str, Any]:
    """Machine, device, torch threads, commit and the load while the benchmark ran."""
    load = os.getloadavg() if hasattr(os, 'getloadavg') else None
    return {
        'machine': {
            'host': platform.node(),
            'processor': platform.processor() or platform.machine(),
            'cpu_count': os.cpu_count(),
            'python': platform.python_version(),
            'load_average_1_5_15': load,
        },
        'device': torch.cuda.get_device_name(0) if torch.cuda.is_available() else 'cpu',
        'torch': torch.__version__,
        'torch_threads': torch.get_num_threads(),
        'git_commit': git_commit(),
        'unix_time': time.time(),
    }


def emit(document: dict[str, Any]) -> None:
    """Print the result as one JSON document on stdout."""
    json.dump({**document, 'environment': environment()}, sys.stdout, indent=1)
    sys.stdout.write('\n')
