"""Fault cases of the outputs: result folders written over, by two writers, half-way, on a full
disk; runs left incomplete; a recorder and a model artifact whose writes fail.

A full disk is real, not mocked: the process's file size limit (RLIMIT_FSIZE) is lowered while a
case writes (in this process, or inherited by a node started meanwhile); CPython ignores SIGXFSZ,
so a write past the limit fails with EFBIG ('File too large') as on a full disk.
"""

from __future__ import annotations

import contextlib
import json
import re
import resource
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

from fault_kit import Case, Fixtures, Outcome, cli

__all__ = ['output_cases']

#: The file size limit of a full-disk case [bytes]: below a report figure, above run.json.
LIMIT_BYTES = 20_000


@contextlib.contextmanager
def _file_size_limit(limit: int) -> Iterator[None]:
    """Writes past ``limit`` bytes fail (EFBIG) in this process and in children started now."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob('*') if p.is_file()}


def _unchanged(outcome: Outcome, folder: Path, before: dict[str, bytes]) -> Outcome:
    """``outcome``, unless ``folder`` changed under it."""
    if _tree(folder) != before:
        return Outcome('data_lost', f'{folder} changed: {outcome.said}')
    return outcome


def _nothing_at(outcome: Outcome, *paths: Path) -> Outcome:
    """``outcome``, unless something was left at one of ``paths`` (half-written)."""
    left = [str(p) for p in paths if p.exists() or p.is_symlink()]
    if left and outcome.kind == 'clear_error':
        return Outcome('data_lost', f'left behind {left}: {outcome.said}')
    return outcome


def _incomplete_copy(fx: Fixtures, name: str) -> Path:
    """The fixture run as a killed ``train`` leaves it: ``<name>.partial``, marker and all."""
    from id_learning.outputs import INCOMPLETE_FILE, partial_path

    assert fx.run_dir is not None
    folder = partial_path(fx.path(name))
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(fx.run_dir, folder)
    (folder / 'metrics.json').unlink()
    document = json.loads((folder / 'run.json').read_text())
    document.update(status='incomplete', requested_kinds=['rnea_lq', 'mlp'])
    (folder / 'run.json').write_text(json.dumps(document))
    (folder / INCOMPLETE_FILE).write_text(json.dumps({'command': 'train', 'pid': 999_999_999}))
    return fx.path(name)


def _recorder_on_a_full_disk(fx: Fixtures) -> Outcome:
    """A recorder whose writes fail: non-zero exit, one error, and recover gives back every
    message it says it wrote."""
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return Outcome('handled', 'skipped: rclpy is not installed')
    from fault_cases_nodes import _nodes, _wait_until

    from id_learning.bag.recover import recover_bag

    out = fx.path('full_disk_bag')
    shutil.rmtree(out, ignore_errors=True)
    with _nodes(fx.path('full_disk_logs')) as (start, _):
        with _file_size_limit(LIMIT_BYTES):  # the recorder inherits it, nothing else does
            recorder = start('recorder', {'output': str(out), 'chunk_kib': 4,
                                          'flush_period_s': 0.1}, {})  # fmt: skip
        start('replay', {'bag': str(fx.bag), 'rate': 4.0, 'reference_mode': 'none',
                         'publish_clock': False, 'wait_for_subscribers': 2}, {})  # fmt: skip
        _wait_until(lambda: not recorder.is_running)
        status = recorder.stop()
        said = recorder.log()
    if status == 0:
        return Outcome('silently_accepted', said[-400:])
    if 'Traceback' in said or 'File too large' not in said or str(out) not in said:
        return Outcome('traceback' if 'Traceback' in said else 'silently_accepted', said[-400:])
    written = {
        topic: int(count)
        for topic, count in re.findall(r'^\s+(/\w+): received \d+, written (\d+)', said, re.M)
    }
    report = recover_bag(out)
    kept = {t.name: t.count for t in report.topics}
    short = {
        topic: (kept.get(topic, 0), n) for topic, n in written.items() if kept.get(topic, 0) < n
    }
    if not written or short:
        return Outcome('data_lost', f'recovered < written: {short}; {said[-300:]}')
    return Outcome('clear_error', f'exit {status}; written {written}, recovered {kept}')


def output_cases(fx: Fixtures) -> Iterator[Case]:
    """The cases; those that need the fixture run are left out without one."""
    bag = str(fx.bag)

    def train(out: Path, *extra: str) -> list[str]:
        return ['train', '--bag', bag, '--models', 'rnea_lq', '--out', str(out), '--quiet',
                *extra]  # fmt: skip

    def dangling_link() -> Outcome:
        link = fx.path('out_dangling')
        link.unlink(missing_ok=True)
        link.symlink_to(fx.path('nowhere_at_all'))
        return cli(train(link), expect=('out_dangling', 'symbolic link', 'does not exist'))

    def regular_file() -> Outcome:
        path = fx.path('out_file')
        path.write_text('mine')
        outcome = cli(train(path, '--force'), expect=('out_file', 'not a folder'))
        return outcome if path.read_text() == 'mine' else Outcome('data_lost', 'file replaced')

    def not_ours() -> Outcome:
        folder = fx.path('out_not_ours')
        folder.mkdir(exist_ok=True)
        (folder / 'notes.txt').write_text('mine')
        before = _tree(folder)
        argv = ['diagnose', '--bag', bag, '--out', str(folder), '--quiet', '--force']
        return _unchanged(cli(argv, expect=('out_not_ours', 'not an id_learning result')),
                          folder, before)  # fmt: skip

    def second_writer() -> Outcome:
        import os

        from id_learning.outputs import result_folder

        out = fx.path('out_two_writers')
        with result_folder(out, command='train', force=True):  # the first writer, still busy
            return cli(train(out, '--force'), expect=('out_two_writers', f'pid {os.getpid()}'))

    yield Case('output a dangling symlink', 'train', dangling_link)
    yield Case('output a regular file', 'train', regular_file)
    yield Case('output a folder that is not a result, with --force', 'diagnose', not_ours)
    yield Case('two trains on one output', 'train', second_writer)
    yield from _kind_cases(fx)
    if fx.run_dir is None:
        return
    yield from _run_cases(fx)


def _kind_cases(fx: Fixtures) -> Iterator[Case]:
    """--force replaces only its own kind, never an input; output paths checked before work.

    The results written over are stand-ins (their documents only): every case is refused before
    any work, so none trains, simulates or reads a bag.
    """
    bag, twin = str(fx.bag), 'config/twin_default.yaml'

    def stand_in(name: str, *documents: str) -> Path:
        folder = fx.path(name)
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        for document in documents:
            (folder / document).write_text('{}')
        return folder

    def over(
        name: str,
        documents: tuple[str, ...],
        argv: Callable[[Path], list[str]],
        words: tuple[str, ...],
    ) -> Callable[[], Outcome]:
        def case() -> Outcome:
            folder = stand_in(name, *documents)
            before = _tree(folder)
            return _unchanged(cli(argv(folder), expect=(name, *words)), folder, before)

        return case

    run, diagnosis = ('run.json', 'metrics.json'), ('effects.json',)
    only = 'replaces only'
    commands: dict[str, Callable[[Path], list[str]]] = {
        'demo': lambda out: [
            'demo',
            '--bag',
            bag,
            '--out',
            str(out),
            '--skip-training',
            '--force',
        ],
        'diagnose': lambda out: ['diagnose', '--bag', bag, '--out', str(out), '--force'],
        'simulate': lambda out: ['simulate', '--config', twin, '--out', str(out), '--force'],
        'import': lambda out: [
            'import',
            str(fx.bag / 'metadata.yaml'),
            '--mapping',
            'config/import_example.yaml',
            '--out',
            str(out),
            '--force',
        ],
        'sweep': lambda out: ['sweep', '--bag', bag, '--model', 'mlp', '--out', str(out)],
    }
    for command, argv in commands.items():
        yield Case(
            f'{command} over a train run',
            command,
            over(f'kind_{command}_over_run', run, argv, ('train run', only)),
        )
    train = lambda out: ['train', '--bag', bag, '--out', str(out), '--force']  # noqa: E731
    yield Case(
        'train over a diagnosis, with --force',
        'train',
        over('kind_train_over_diagnosis', diagnosis, train, ('diagnosis', only)),
    )

    def import_over_inputs() -> Outcome:
        folder = stand_in('kind_import_inputs', 'm.yaml')
        (folder / 'log.csv').write_text('t\n0\n')
        before = _tree(folder)
        argv = [
            'import',
            str(folder / 'log.csv'),
            '--mapping',
            str(folder / 'm.yaml'),
            '--out',
            str(folder),
            '--force',
        ]
        return _unchanged(cli(argv, expect=('kind_import_inputs', 'input')), folder, before)

    def train_inside_its_bag() -> Outcome:
        out = fx.bag / 'sub'
        outcome = cli(['train', '--bag', bag, '--out', str(out)], expect=('lies inside', 'input'))
        return outcome if not out.exists() else Outcome('data_lost', f'wrote into {fx.bag}')

    def plot_over(target: Callable[[], Path], words: tuple[str, ...]) -> Callable[[], Outcome]:
        def case() -> Outcome:
            path = target()
            folder = path if path.is_dir() else path.parent
            ours = fx.root in folder.parents  # what may change is only looked at under ours
            before = _tree(folder) if ours else {}
            argv = ['inspect', str(fx.path('kind_no_bag')), '--plot', str(path), '--force']
            outcome = cli(argv, expect=words)  # the bag does not exist: checked first
            return _unchanged(outcome, folder, before) if ours else outcome

        return case

    def afile() -> Path:
        path = fx.path('kind_a_file')
        path.write_text('mine')
        return path

    def over_file(argv: Callable[[Path], list[str]]) -> Outcome:
        path = afile()
        outcome = cli(argv(path), expect=('a file',))
        return outcome if path.read_text() == 'mine' else Outcome('data_lost', 'file replaced')

    yield Case(
        'import into the folder holding its inputs, with --force', 'import', import_over_inputs
    )
    yield Case('train into a folder inside its bag', 'train', train_inside_its_bag)
    yield Case(
        "inspect --plot over a run's metrics.json",
        'inspect',
        plot_over(
            lambda: stand_in('kind_plot_run', *run) / 'metrics.json',
            ('metrics.json', 'not a file type'),
        ),
    )
    yield Case(
        'inspect --plot into a folder',
        'inspect',
        plot_over(lambda: stand_in('kind_plot_dir.png'), ('is a folder',)),
    )
    yield Case(
        'inspect --plot under /proc',
        'inspect',
        plot_over(lambda: Path('/proc/x.png'), ('/proc', 'cannot write')),
    )
    for command in ('simulate', 'import'):
        argv = commands[command]
        yield Case(
            f'{command} --out a regular file, with --force',
            command,
            lambda argv=argv: over_file(argv),
        )
    yield Case(
        'simulate --out under /proc',
        'simulate',
        lambda: cli(commands['simulate'](Path('/proc/x')), expect=('/proc', 'cannot')),
    )
    yield Case(
        'recorder over a train run, overwrite:=true',
        'recorder',
        lambda: _recorder_over(stand_in('kind_recorder_run', *run)),
    )


def _recorder_over(run: Path) -> Outcome:
    """A recorder whose output is a train run: refused at start, exit 2, the run untouched."""
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return Outcome('handled', 'skipped: rclpy is not installed')
    import subprocess
    import sys

    before = _tree(run)
    done = subprocess.run(
        [sys.executable, '-m', 'id_learning.nodes.recorder', '--ros-args', '-p',
         f'output:={run}', '-p', 'overwrite:=true'],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    said = done.stdout + done.stderr
    if done.returncode == 0:
        return Outcome('silently_accepted', said[-400:])
    if 'Traceback' in said:
        return Outcome('traceback', said[-400:])
    words = ('train run', 'replaces only a bag')
    kind = 'clear_error' if all(word in said for word in words) else 'silently_accepted'
    return _unchanged(Outcome(kind, said[-400:]), run, before)


def _run_cases(fx: Fixtures) -> Iterator[Case]:
    """Cases on the fixture run: evaluations over it, an interrupted copy, full disks."""
    assert fx.run_dir is not None
    # The run's own training bag (its test part is scored): fx.bag holds the same samples under
    # another hash, which evaluate refuses as training samples scored as unseen.
    run, bag = fx.run_dir, str(fx.path('twin'))

    def evaluate(out: Path, *extra: str, run_dir: Path = run) -> list[str]:
        return ['evaluate', '--run', str(run_dir), '--bag', bag, '--out', str(out), '--quiet',
                *extra]  # fmt: skip

    def into_itself() -> Outcome:
        before = _tree(run)
        return _unchanged(cli(evaluate(run, '--force'), expect=('input',)), run, before)

    def into_another(name: str, document: str) -> Callable[[], Outcome]:
        def case() -> Outcome:
            other = fx.path(name)
            shutil.rmtree(other, ignore_errors=True)
            other.mkdir()
            shutil.copy(run / document, other / document)
            before = _tree(other)
            return _unchanged(cli(evaluate(other), expect=(name, '--force')), other, before)

        return case

    def interrupted(
        command: str, words: tuple[str, ...], name: str, *, at_partial: bool = True
    ) -> Callable[[], Outcome]:
        def case() -> Outcome:
            from id_learning.outputs import partial_path

            folder = _incomplete_copy(fx, name)
            folder = partial_path(folder) if at_partial else folder
            argv = (evaluate(fx.path(f'{name}_eval'), run_dir=folder) if command == 'evaluate'
                    else ['closed-loop', '--run', str(folder), '--out',
                          str(fx.path(f'{name}_loop')), '--quiet'])  # fmt: skip
            return cli(argv, expect=words)

        return case

    def full_disk_figure() -> Outcome:
        from id_learning.outputs import partial_path

        out = fx.path('eval_full_disk')
        with _file_size_limit(LIMIT_BYTES):
            outcome = cli(evaluate(out), expect=('eval_full_disk', 'File too large'))
        if 'Traceback' in outcome.said:
            return Outcome('traceback', outcome.said)
        return _nothing_at(outcome, out, partial_path(out))

    def full_disk_artifact() -> Outcome:
        from id_learning.models.registry import load_model, save_model

        model = load_model(fx.artifact, fx.robot)  # type: ignore[arg-type]
        folder = fx.path('artifact_full_disk')
        try:
            with _file_size_limit(300):  # below weights.safetensors
                save_model(model, folder)
        except OSError as error:
            words = ('artifact_full_disk', 'File too large')
            missing = [w for w in words if w.lower() not in f'{error.filename} {error}'.lower()]
            outcome = Outcome('clear_error' if not missing else 'silently_accepted', str(error))
            left = [p.name for p in folder.parent.glob('*artifact_full_disk*')]
            return Outcome('data_lost', f'half an artifact left: {left}') if left else outcome
        return Outcome('silently_accepted', 'saved past the file size limit')

    def force_over_notes() -> Outcome:
        from id_learning.outputs import result_folder

        out = fx.path('eval_with_notes')
        shutil.rmtree(out, ignore_errors=True)
        with result_folder(out, command='evaluate') as folder:  # an evaluation, manifest and all
            (folder.work / 'metrics.json').write_text('{}')
        (out / 'my_notes.txt').write_text('precious')
        before = _tree(out)
        outcome = cli(evaluate(out, '--force'), expect=('eval_with_notes', 'my_notes.txt'))
        return _unchanged(outcome, out, before)

    def partial_is_a_file() -> Outcome:
        from id_learning.outputs import partial_path

        out = fx.path('eval_partial_file')
        partial = partial_path(out)
        partial.write_text('precious')
        outcome = cli(evaluate(out, '--force'), expect=('eval_partial_file.partial', 'not an'))
        kept = partial.is_file() and partial.read_text() == 'precious'
        return outcome if kept else Outcome('data_lost', f'{partial} replaced: {outcome.said}')

    def plot_in_a_model() -> Outcome:
        inner = next((p for p in sorted(run.rglob('*')) if p.is_dir()), run)
        argv = ['inspect', bag, '--plot', str(inner / 'x.png')]
        outcome = cli(argv, expect=('x.png', 'holds'))
        return outcome if not (inner / 'x.png').exists() else Outcome('data_lost', 'plot written')

    yield Case('evaluate into the evaluated run, with --force', 'evaluate', into_itself)
    yield Case('evaluate --force over an evaluation holding a user file', 'evaluate',
               force_over_notes)  # fmt: skip
    yield Case('evaluate --force where <out>.partial is a user file', 'evaluate',
               partial_is_a_file)  # fmt: skip
    yield Case('inspect --plot inside a model folder of a run', 'inspect', plot_in_a_model)
    yield Case('evaluate into another run', 'evaluate', into_another('out_other_run', 'run.json'))
    yield Case('evaluate into an earlier evaluation', 'evaluate',
               into_another('out_earlier_eval', 'metrics.json'))  # fmt: skip
    words = ('incomplete', 'holds 1 of 2 model', '--force')
    yield Case('evaluate an interrupted run', 'evaluate',
               interrupted('evaluate', words, 'killed_run'))  # fmt: skip
    only_partial = interrupted('evaluate', ('only', '.partial'), 'only_partial', at_partial=False)
    yield Case('evaluate a run of which only the partial folder exists', 'evaluate', only_partial)
    yield Case('closed loop on an interrupted run', 'closed-loop',
               interrupted('closed-loop', words, 'killed_run_loop'))  # fmt: skip
    yield Case('evaluate on a full disk (a figure fails)', 'evaluate', full_disk_figure)
    yield Case('model artifact saved on a full disk', 'train', full_disk_artifact)
    yield Case('recorder on a full disk', 'recorder', lambda: _recorder_on_a_full_disk(fx))
