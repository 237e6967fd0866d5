"""The manual's generated references are current, and every command and option it names exists.

``tools/gen_reference.py`` writes docs/reference/cli.md (from the argparse parsers) and
docs/reference/node_parameters.md (from the node config dataclasses). The rest of the manual and
the README are written by hand: each ``id-learning <command>`` and ``--option`` in them is
checked against the parsers, and each option given to ``benchmarks/<name>.py`` against that
script, so that a renamed command or option fails here rather than in a reader's shell.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
from collections.abc import Iterator
from dataclasses import dataclass
from types import ModuleType

import pytest
from support import REPO


def load_generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        'gen_reference', REPO / 'tools' / 'gen_reference.py'
    )
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


GEN = load_generator()

#: Hand-written pages: the README and the manual (not the pages benchmarks write).
PAGES = [
    REPO / 'README.md',
    *sorted(
        path
        for path in (REPO / 'docs').rglob('*.md')
        if path.relative_to(REPO / 'docs').parts[0] != 'results'
    ),
]
#: Programs whose options are not ours: their words are not checked.
FOREIGN_PROGRAMS = {
    'bash', 'cd', 'colcon', 'createdb', 'git', 'make', 'mypy', 'pip', 'pytest', 'python3',
    'rm', 'ruff', 'source', 'sphinx-build', 'ros2',
}  # fmt: skip
#: Options of other programs that the pages name on their own, outside a command line.
FOREIGN_OPTIONS = {
    '--ros-args',  # ros2 run / ros2 launch
    '--params-file',  # ros2 run ... --ros-args
    '--return-code-on-test-failure',  # colcon test
    '--system-site-packages',  # python -m venv
    '--keep-going',  # sphinx-build (make docs)
}
OPTION = re.compile(r'(?<![\w-])--[a-z][a-z0-9-]*')
COMMAND_WORD = re.compile(r'[a-z][a-z-]*')
SEPARATORS = {'&&', '||', ';', '|'}


@dataclass(frozen=True)
class Problem:
    page: str
    line: int
    text: str
    reason: str

    def __str__(self) -> str:
        return f'{self.page}:{self.line}: {self.reason} in {self.text!r}'


class Parsers:
    """What the id-learning parsers accept: command paths and their options."""

    def __init__(self) -> None:
        parser = GEN.build_parser()
        self.global_options = set(option_strings(parser))
        self.options: dict[tuple[str, ...], set[str]] = {(): set(self.global_options)}
        for words, sub, _ in GEN.commands(parser):
            self.options[words] = set(option_strings(sub)) | self.global_options
        self.every_option = set().union(*self.options.values())

    def is_command(self, words: tuple[str, ...]) -> bool:
        return words in self.options


def option_strings(parser: argparse.ArgumentParser) -> Iterator[str]:
    for action in parser._actions:
        yield from action.option_strings


def benchmark_options(name: str) -> set[str] | None:
    """The options a benchmark script defines (its text, and the shared helpers'), or None."""
    path = REPO / 'benchmarks' / name
    if not path.is_file():
        return None
    text = path.read_text(encoding='utf-8') + (REPO / 'benchmarks/common.py').read_text('utf-8')
    return set(re.findall(r"['\"](--[a-z][a-z0-9-]*)['\"]", text))


def snippets(markdown: str) -> Iterator[tuple[int, str, bool, set[str]]]:
    """(line, text, is code, options) of every command line, inline code span and paragraph.

    Lines of a fenced block are joined across trailing backslashes, comments dropped; fences
    of MyST directives (```{toctree}) are skipped. Inline code may run across the lines of a
    paragraph. *options*: those of the benchmarks the paragraph names, which an option on its
    own there may be.
    """
    fence: str | None = None
    is_directive = False
    pending, start = '', 0
    paragraph: list[str] = []
    for number, line in enumerate([*markdown.splitlines(), ''], start=1):
        stripped = line.strip()
        if fence is None:
            opening = re.match(r'(`{3,}|~{3,})(.*)', stripped)
            if paragraph and (not stripped or opening):
                yield from paragraph_snippets(number - len(paragraph), ' '.join(paragraph))
                paragraph = []
            if opening:
                fence, is_directive = opening.group(1), opening.group(2).startswith('{')
            elif stripped:
                paragraph.append(line)
            continue
        if stripped.startswith(fence) and not stripped.strip('`~'):
            fence = None
            continue
        if is_directive:
            continue
        code = re.sub(r'(^|\s)#.*$', '', line)
        if not pending:
            start = number
        if code.rstrip().endswith('\\'):
            pending += code.rstrip()[:-1] + ' '
            continue
        yield start, pending + code, True, set()
        pending = ''


def paragraph_snippets(number: int, text: str) -> Iterator[tuple[int, str, bool, set[str]]]:
    """The inline code spans of a paragraph, then the prose around them."""
    named: set[str] = set()
    for name in re.findall(r'benchmarks/(\w+\.py)', text):
        named |= benchmark_options(name) or set()
    span = re.compile(r'(`+)(.+?)\1')
    for match in span.finditer(text):
        yield number, match.group(2).strip(), True, named
    yield number, span.sub(' ', text), False, named


def check_code(text: str, parsers: Parsers, nearby: set[str]) -> Iterator[str]:
    """Why a command line or code span names a command or option that does not exist.

    An option outside a command line may be any command's, or one of ``nearby``.
    """
    tokens = [token.strip('"\'(),.;:') for token in text.split()]
    tokens = [token for token in tokens if token]
    context: str | None = None  # 'cli', 'benchmark', 'foreign' or None (no program yet)
    path: tuple[str, ...] = ()
    allowed: set[str] | None = None
    at_start = True
    index = 0
    while index < len(tokens):
        token = tokens[index]
        index += 1
        if token in SEPARATORS:
            context, path, allowed, at_start = None, (), None, True
            continue
        is_cli = token == 'id-learning' or token.endswith('/id-learning')
        if token == 'id_learning.cli' or is_cli:
            context, path = 'cli', ()
            while index < len(tokens) and COMMAND_WORD.fullmatch(tokens[index]):
                if not parsers.is_command((*path, tokens[index])):
                    if not path:
                        yield f'no command id-learning {tokens[index]}'
                    break
                path = (*path, tokens[index])
                index += 1
            allowed = parsers.options[path] if path else parsers.every_option
        elif token.startswith('benchmarks/') and token.endswith('.py'):
            context, allowed = 'benchmark', benchmark_options(token.split('/', 1)[1])
            if allowed is None:
                yield f'no benchmark {token}'
                context = 'foreign'
        elif at_start and (token in FOREIGN_PROGRAMS or token == 'python'):
            context = 'foreign'
            if token == 'ros2' and tokens[index : index + 3] == ['run', 'id_learning', 'train']:
                context, path, allowed = 'cli', ('train',), parsers.options[('train',)]
                index += 3
        elif at_start and parsers.is_command((token,)):
            context, path, allowed = 'cli', (token,), parsers.options[(token,)]
        elif OPTION.fullmatch(token.split('=', 1)[0]):
            option = token.split('=', 1)[0]
            if context is None and option not in parsers.every_option | FOREIGN_OPTIONS | nearby:
                yield f'no option {option} in any id-learning command'
            elif context in ('cli', 'benchmark') and allowed is not None and option not in allowed:
                where = 'id-learning ' + ' '.join(path) if context == 'cli' else 'the benchmark'
                yield f'no option {option} in {where.strip()}'
        at_start = False


def check_prose(text: str, parsers: Parsers, nearby: set[str]) -> Iterator[str]:
    """Why prose (outside code) names a command or option that does not exist."""
    for option in OPTION.findall(text):
        if option not in parsers.every_option | FOREIGN_OPTIONS | nearby:
            yield f'no option {option} in any id-learning command'
    for word in re.findall(r'(?<![\w/-])id-learning\s+([a-z][a-z-]*)', text):
        if not parsers.is_command((word,)):
            yield f'no command id-learning {word}'


def problems(markdown: str, page: str, parsers: Parsers) -> list[Problem]:
    found = []
    for number, text, is_code, nearby in snippets(markdown):
        check = check_code if is_code else check_prose
        found += [Problem(page, number, text.strip(), why) for why in check(text, parsers, nearby)]
    return found


@pytest.fixture(scope='module')
def parsers() -> Parsers:
    return Parsers()


def test_the_generated_references_are_what_the_code_generates_now():
    stale = [
        str(path)
        for path, text in GEN.render().items()
        if not (REPO / path).is_file() or (REPO / path).read_text(encoding='utf-8') != text
    ]
    assert not stale, (
        f'stale: {", ".join(stale)} (not what the parsers and node configs give now); '
        'run `python tools/gen_reference.py`'
    )


def test_every_command_and_option_the_pages_name_exists(parsers):
    assert len(PAGES) > 5, PAGES  # the README and the manual were found
    found = []
    for page in PAGES:
        text = page.read_text(encoding='utf-8')
        found += problems(text, str(page.relative_to(REPO)), parsers)
    assert not found, '\n'.join(str(problem) for problem in found)


@pytest.mark.parametrize(
    ('markdown', 'reason'),
    [
        ('Run `id-learning trian --bag b`.', 'no command id-learning trian'),
        ('```bash\nid-learning train --bags b \\\n    --out o\n```', 'no option --bags in'),
        ('```bash\nid-learning train --bag b \\\n    --outt o\n```', 'no option --outt in'),
        ('`id-learning bag recover --force`', 'no option --force in id-learning bag recover'),
        ('`train --hyper-files x`', 'no option --hyper-files in id-learning train'),
        ('Pass `--split-seeds 3`.', 'no option --split-seeds in any'),
        ('Pass --skip-trainig to demo.', 'no option --skip-trainig in any'),
        ('`benchmarks/faults.py` takes `--onlyy`.', 'no option --onlyy in any'),
        ('`python benchmarks/faults.py --onlyy x`', 'no option --onlyy in the benchmark'),
        ('`python benchmarks/no_such.py`', 'no benchmark benchmarks/no_such.py'),
    ],
)
def test_the_check_catches_a_renamed_command_or_option(parsers, markdown, reason):
    found = problems(markdown, 'page.md', parsers)
    assert [problem.reason for problem in found if problem.reason.startswith(reason)], found


def test_the_check_passes_what_exists(parsers):
    markdown = (
        '`id-learning bag recover PATH --out new`, `id-learning COMMAND --help`, '
        '`ros2 run id_learning predictor --ros-args -p artifact:=x`, `--preprocessing study`\n'
        '\n`benchmarks/faults.py` takes `--only`.\n'
        '```bash\nid-learning sweep --bag b --model mlp --out o && id-learning train --bag b \\\n'
        '    --models mlp --hyper-file o/best.yaml --out r   # --not-checked\n'
        'python benchmarks/faults.py --only bag\n```\n'
    )
    assert problems(markdown, 'page.md', parsers) == []
