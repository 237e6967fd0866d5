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


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), else what platform says."""
    try:
        for line in Path('/proc/cpuinfo').read_text(encoding='utf-8').splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def write_results(
    name: str, document: dict[str, Any], markdown: list[str], folder: Path | None = None
) -> tuple[Path, Path]:
    """Write a benchmark's figures to docs/results/NAME.json and NAME.md.

    Both carry the commit, the machine (cores, CPU model) and the date; ``markdown`` is the
    body of the .md, below that header. Returns the two paths.
    """
    folder = folder or REPO / 'docs' / 'results'
    folder.mkdir(parents=True, exist_ok=True)
    env = environment()
    env['machine']['cpu_model'] = cpu_model()
    date = time.strftime('%Y-%m-%d %H:%M:%S %Z', time.localtime(env['unix_time']))
    env['date'] = date
    json_path, md_path = folder / f'{name}.json', folder / f'{name}.md'
    json_path.write_text(
        json.dumps({**document, 'environment': env}, indent=1, default=str) + '\n',
        encoding='utf-8',
    )
    machine = env['machine']
    load = machine['load_average_1_5_15']
    load_text = '/'.join(f'{x:.2f}' for x in load) if load else 'unknown'
    header = [
        f'# {name}',
        '',
        f'Written by `benchmarks/{name}.py` on {date}; commit `{env["git_commit"]}`; machine '
        f'{machine["host"]}: {machine["cpu_count"]} cores, {machine["cpu_model"]}, load '
        f'{load_text}; torch {env["torch"]} ({env["torch_threads"]} '
        f'threads), device {env["device"]}. The figures in full: `{json_path.name}`.',
        '',
    ]
    md_path.write_text('\n'.join([*header, *markdown]).rstrip() + '\n', encoding='utf-8')
    return json_path, md_path
