"""What every benchmark records beside its numbers: machine, torch threads, git commit, load."""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
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


# -- the results pages: options, settings, tables -------------------------------------------------
#: Options that say where the figures go, not how they are measured.
_OUTPUT_OPTIONS = ('help', 'no_results', 'results_folder')


def add_results_options(parser: argparse.ArgumentParser) -> None:
    """``--no-results`` (print only), ``--results-folder`` (another folder than docs/results)."""
    parser.add_argument('--no-results', action='store_true', help='do not write docs/results')
    parser.add_argument(
        '--results-folder',
        type=Path,
        help='write the results page and its JSON here instead of docs/results',
    )


def repo_path(path: str | Path) -> str:
    """A path as the reader would type it: from the repository, where it is in or beside it."""
    resolved = Path(path).resolve()
    if resolved.is_relative_to(REPO):
        return str(resolved.relative_to(REPO))
    if resolved.is_relative_to(REPO.parent):
        return os.path.relpath(resolved, REPO)
    return str(path)


def _option_text(value: Any, separator: str = ' ') -> str:
    """A setting as typed: paths from the repository, lists by ``separator``."""
    if isinstance(value, Path):
        return repo_path(value)
    if isinstance(value, (list, tuple)):
        return separator.join(_option_text(v) for v in value)
    if isinstance(value, float):
        return f'{value:g}'
    return str(value)


def changed_settings(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> list[tuple[str, str, str]]:
    """(option, value, default) of every option whose value is not its default."""
    changed = []
    for action in parser._actions:
        if action.dest in _OUTPUT_OPTIONS or not action.option_strings:
            continue
        value, default = getattr(args, action.dest, None), action.default
        if value == default or (isinstance(value, Path) and default is not None
                                and Path(default).resolve() == value.resolve()):  # fmt: skip
            continue
        option = max(action.option_strings, key=len)
        # A list from one word (a type that splits it) was typed comma-separated.
        separator = ' ' if action.nargs in ('+', '*') or isinstance(action.nargs, int) else ','
        shown = '' if action.nargs == 0 else _option_text(value, separator)
        shown_default = 'unset' if default is None else _option_text(default, separator)
        changed.append((option, shown, shown_default))
    return changed


def settings_lines(
    name: str, parser: argparse.ArgumentParser, args: argparse.Namespace
) -> list[str]:
    """The command line of this run and, where it left the defaults, which settings it changed."""
    changed = changed_settings(parser, args)
    command = ' '.join(
        [f'python benchmarks/{name}.py', *(f'{o} {v}'.rstrip() for o, v, _ in changed)]
    )
    if not changed:
        return [f'Run: `{command}`, every setting at its default.', '']
    differs = ', '.join(f'`{o}` (default {d})' for o, _, d in changed)
    return [f'Run: `{command}`; not the default run: {differs}.', '']


def publish_results(
    name: str, document: dict[str, Any], markdown: list[str], args: argparse.Namespace
) -> tuple[Path, Path] | None:
    """``write_results`` unless ``--no-results``, into ``--results-folder`` where given."""
    if getattr(args, 'no_results', False):
        return None
    paths = write_results(name, document, markdown, getattr(args, 'results_folder', None))
    print(f'wrote {paths[0]} and {paths[1]}', file=sys.stderr)
    return paths


def finish(
    name: str, document: dict[str, Any], markdown: list[str], args: argparse.Namespace
) -> None:
    """The end of a run: the page on stderr, written (``publish_results``), the JSON on stdout."""
    print('\n'.join(markdown), file=sys.stderr)
    publish_results(name, document, markdown, args)
    emit(document)


def number(value: Any, spec: str = '.3g', missing: str = '-') -> str:
    """A figure as text; None and NaN as ``missing``."""
    if value is None:
        return missing
    try:
        if math.isnan(float(value)):
            return missing
    except (TypeError, ValueError):
        return str(value)
    return format(value, spec)


def share(value: float | None) -> str:
    """A fraction as a percentage."""
    return number(None if value is None else 100.0 * value, '.0f') + (
        ' %' if value is not None and not math.isnan(value) else ''
    )


def verdict(passed: bool | None) -> str:
    """pass, fail, or '-' where nothing was judged."""
    return '-' if passed is None else ('pass' if passed else 'fail')


def markdown_table(
    header: Sequence[str], rows: Iterable[Sequence[Any]], align: str | None = None
) -> list[str]:
    """A markdown table; ``align`` one letter per column (l or r; default: first l, rest r)."""
    align = align or 'l' + 'r' * (len(header) - 1)
    rule = ['---' if a == 'l' else '---:' for a in align]
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '|'.join(rule) + '|']
    lines += ['| ' + ' | '.join(str(cell) for cell in row) + ' |' for row in rows]
    return lines
