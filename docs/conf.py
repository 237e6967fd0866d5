"""Sphinx configuration of the id_learning manual (``make docs`` builds it into build/docs).

Markdown pages through myst-parser; the API reference from the package's docstrings: one page
per subpackage, written at build time into api/generated/ (git-ignored) and filled by autodoc,
with napoleon for the Google-style sections. ROS modules are mocked, so that the reference builds
where ROS is not installed. No extension reaches the network (no intersphinx).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import id_learning  # noqa: E402

project = 'id_learning'
author = 'the id_learning authors'
project_copyright = 'the id_learning authors'
release = version = id_learning.__version__

extensions = ['myst_parser', 'sphinx.ext.autodoc', 'sphinx.ext.napoleon']
source_suffix = {'.md': 'markdown', '.rst': 'restructuredtext'}
root_doc = 'index'
exclude_patterns = ['_build']

myst_enable_extensions = ['colon_fence', 'deflist']
myst_heading_anchors = 3

autodoc_default_options = {'show-inheritance': True}
autodoc_member_order = 'bysource'
napoleon_google_docstring = True
napoleon_numpy_docstring = False
highlight_language = 'none'  # literal blocks in docstrings are formulas, not Python

html_theme = 'furo'
html_title = 'id_learning'

#: Modules ROS provides: mocked, so that the reference builds where ROS is not installed.
autodoc_mock_imports = [
    'ament_index_python',
    'builtin_interfaces',
    'diagnostic_msgs',
    'rcl_interfaces',
    'rclpy',
    'rosgraph_msgs',
    'sensor_msgs',
    'std_msgs',
    'trajectory_msgs',
]


API_FOLDER = Path(__file__).parent / 'api' / 'generated'


def _modules(package: Any) -> list[str]:
    """The modules below a package, by name (``_``-modules such as ``__main__`` left out)."""
    return sorted(
        info.name
        for info in pkgutil.walk_packages(package.__path__, f'{package.__name__}.')
        if not any(part.startswith('_') for part in info.name.split('.'))
    )


def _page(title: str, sections: list[tuple[str, str]]) -> str:
    """An API page of ``automodule`` sections, each with its options (one per line)."""
    lines = [title, '=' * len(title), '']
    for name, options in sections:
        lines.append(f'.. automodule:: {name}')
        lines += [f'   {option}' for option in options.split(';') if option]
        lines.append('')
    return '\n'.join(lines)


def api_pages() -> dict[str, str]:
    """One page per subpackage: its public API (``__all__``), then every module's docstring.

    The top page holds the package's own modules (errors, config and output helpers) with the
    members each defines. A module a package exports by name (``id_learning.nodes``) shows its
    public members too; one whose name an exported function shadows is not indexed twice.
    """
    top = [('id_learning', ':no-members:')]
    pages = {}
    for info in sorted(pkgutil.iter_modules(id_learning.__path__), key=lambda i: i.name):
        name = f'id_learning.{info.name}'
        if info.name.startswith('_'):
            continue
        if not info.ispkg:
            top.append((name, ':members:;:ignore-module-all:'))
            continue
        package = importlib.import_module(name)
        exported = set(getattr(package, '__all__', ()))
        sections = [(name, ':members:')]
        for module in _modules(package):
            leaf = module.rsplit('.', 1)[-1]
            if leaf not in exported:
                sections.append((module, ':no-members:'))
            elif inspect.ismodule(getattr(package, leaf, package)):  # not imported: the module
                sections.append((module, ':members:'))
            else:  # a function of the package's API has the module's name
                sections.append((module, ':no-members:;:no-index:'))
        pages[name] = _page(name, sections)
    pages['id_learning'] = _page('id_learning', top)
    return pages


def write_api_pages(app: Any) -> None:
    """Write the API pages into api/generated/; files already equal are left alone."""
    API_FOLDER.mkdir(parents=True, exist_ok=True)
    wanted = {f'{name}.rst': text for name, text in api_pages().items()}
    for path in API_FOLDER.glob('*.rst'):
        if path.name not in wanted:
            path.unlink()
    for file_name, text in wanted.items():
        path = API_FOLDER / file_name
        if not path.is_file() or path.read_text(encoding='utf-8') != text:
            path.write_text(text, encoding='utf-8')


_INLINE_LITERAL = re.compile(r'(``.*?``)')
_BULLET = re.compile(r'\s*(?:[-*+]|\d+\.|\(\w+\))\s+')


def _content_indent(line: str) -> int:
    """Where a line's text starts (after a list bullet, if any)."""
    bullet = _BULLET.match(line)
    return bullet.end() if bullet else len(line) - len(line.lstrip())


def plain_docstring(  # noqa: PLR0917 (the signature of autodoc-process-docstring)
    app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    """Read the package's plain-text docstrings as reStructuredText does not by itself.

    - A block indented under a paragraph that does not end in ``:`` (a formula) is a literal
      block, as if the paragraph ended in ``::``.
    - ``|`` outside literals is escaped: the docstrings write ``|v|`` for an absolute value,
      which reStructuredText reads as a substitution.
    """
    last = -1  # the last line with text
    literal_indent = None  # the indent a literal block ends at, while in one
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None and indent <= literal_indent:
            literal_indent = None
        if literal_indent is None and last >= 0:
            previous = lines[last]
            after_blank = last < index - 1
            if (
                after_blank
                and indent > _content_indent(previous)
                and not previous.rstrip().endswith(':')
            ):
                lines[last] = f'{previous.rstrip()} ::'
                literal_indent = len(previous) - len(previous.lstrip())
        if literal_indent is None:
            parts = _INLINE_LITERAL.split(line)
            lines[index] = ''.join(
                part if part.startswith('``') else part.replace('|', r'\|') for part in parts
            )
            if stripped.endswith('::'):
                literal_indent = indent
        last = index


def setup(app: Any) -> None:
    """Write the API pages before reading, and prepare every docstring before napoleon."""
    app.connect('builder-inited', write_api_pages)
    app.connect('autodoc-process-docstring', plain_docstring, priority=400)  # before napoleon
