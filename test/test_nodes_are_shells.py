"""The nodes are thin ROS shells over the core: none imports the trainer or the evaluation."""

from __future__ import annotations

import ast

import pytest
from support import REPO

NODES = REPO / 'id_learning' / 'nodes'
#: The layers above the predictor core that no node may import, not even inside a function.
FORBIDDEN = ('id_learning.training', 'id_learning.evaluation', 'id_learning.online_check',
             'id_learning.cli')  # fmt: skip


def imported_modules(text: str, package: str) -> set[str]:
    """Every module an import anywhere in ``text`` (a module of ``package``) names.

    Function bodies count; relative imports are resolved; ``from a import b`` names both ``a``
    and ``a.b`` (b may be a module); so does ``importlib.import_module`` of a literal name.
    """
    names: set[str] = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')
                parts = parts[: len(parts) - node.level + 1]
                base = '.'.join([*parts, *([node.module] if node.module else [])])
            names.add(base)
            names.update(f'{base}.{alias.name}' for alias in node.names)
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, 'attr', getattr(node.func, 'id', None)) == 'import_module'
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            names.add(node.args[0].value)
    return names


def forbidden(names: set[str]) -> list[str]:
    return sorted(n for n in names if any(n == f or n.startswith(f'{f}.') for f in FORBIDDEN))


@pytest.mark.parametrize('path', sorted(NODES.glob('*.py')), ids=lambda p: p.name)
def test_no_node_module_imports_the_trainer_or_the_evaluation(path):
    names = imported_modules(path.read_text(encoding='utf-8'), 'id_learning.nodes')
    assert not forbidden(names), path.name


def test_the_scan_sees_imports_in_functions_relative_ones_and_import_module():
    assert len(list(NODES.glob('*.py'))) > 10
    text = (
        'import importlib\n'
        'from id_learning.predictor import FeedForwardPredictor\n'
        'def f():\n'
        '    from id_learning.training.run_folder import refuse_incomplete_run\n'
        '    from ..evaluation import scoring\n'
        "    return importlib.import_module('id_learning.cli.main')\n"
    )
    assert forbidden(imported_modules(text, 'id_learning.nodes')) == [
        'id_learning.cli.main',
        'id_learning.evaluation',
        'id_learning.evaluation.scoring',
        'id_learning.training.run_folder',
        'id_learning.training.run_folder.refuse_incomplete_run',
    ]
