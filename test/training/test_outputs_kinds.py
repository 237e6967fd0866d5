"""--force replaces only a result of the command's own kind (or an empty folder), never an input
nor a folder inside one; every output path is checked before any work, in one clear line."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest
from support import REPO

from id_learning.cli.main import main
from id_learning.outputs import (
    MANIFEST_FILE,
    OutputError,
    check_bag_output,
    check_file_output,
    check_kind,
    check_output,
    folder_holds,
    foreign_entries,
    incomplete_reason,
    partial_path,
    result_folder,
)

#: One document per kind of result (what ``folder_holds`` reads).
RESULTS = {
    'run': 'run.json',
    'evaluation': 'metrics.json',
    'closed-loop': 'closed_loop.json',
    'diagnosis': 'effects.json',
    'demo': 'summary.md',
}


def _folder(root, name: str, *files: str):
    folder = root / name
    folder.mkdir()
    for file in files:
        (folder / file).write_text('{}')
    return folder


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob('*') if p.is_file()}


def _cli(capsys, *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.err + captured.out


@pytest.mark.parametrize('kind', sorted(RESULTS))
def test_each_kind_of_folder_is_told_apart(tmp_path, kind):
    assert folder_holds(_folder(tmp_path, 'r', RESULTS[kind])).kind == kind


def test_bags_sweeps_torn_bags_and_foreign_folders_are_told_apart(tmp_path):
    assert folder_holds(_folder(tmp_path, 'empty')).kind == 'empty'
    bag = _folder(tmp_path, 'bag', 'metadata.yaml', 'bag_0.mcap', 'ground_truth.json')
    assert folder_holds(bag).kind == 'bag'
    assert folder_holds(_folder(tmp_path, 'torn', 'torn_0.mcap')).kind == 'torn bag'
    assert folder_holds(_folder(tmp_path, 'mixed', 'metadata.yaml', 'a.mcap', 'x.csv')).kind == (
        'foreign'
    )
    assert folder_holds(_folder(tmp_path, 'sweep', 'sweep.db', 'best.yaml')).kind == 'sweep'
    assert folder_holds(_folder(tmp_path, 'run', 'run.json', 'metrics.json')).kind == 'run'


@pytest.mark.parametrize('kind', sorted(RESULTS))
def test_force_replaces_only_the_same_kind(tmp_path, kind):
    for other, document in RESULTS.items():
        folder = _folder(tmp_path, f'{kind}-{other}', document)
        if other == kind:
            check_output(folder, force=True, kind=kind)
            with pytest.raises(OutputError, match=r'already .*--force'):
                check_output(folder, kind=kind)
        else:
            with pytest.raises(OutputError, match=rf'holds .*\({document}\); --force replaces '):
                check_output(folder, force=True, kind=kind)


def test_a_bag_replaces_only_a_bag_or_an_empty_folder(tmp_path):
    bag = _folder(tmp_path, 'bag', 'metadata.yaml', 'bag_0.mcap')
    assert check_bag_output(bag, overwrite=True) == bag
    with pytest.raises(OutputError, match=r'holds a bag already .*--force'):
        check_bag_output(bag)
    check_bag_output(_folder(tmp_path, 'empty'))
    run = _folder(tmp_path, 'run', 'run.json')
    with pytest.raises(OutputError, match=r'holds a train run \(run\.json\); --force replaces '
                       'only a bag'):  # fmt: skip
        check_bag_output(run, overwrite=True)
    with pytest.raises(OutputError, match='torn bag'):
        check_bag_output(_folder(tmp_path, 'torn', 'torn_0.mcap'), overwrite=True)
    afile = tmp_path / 'afile'
    afile.write_text('x')
    with pytest.raises(OutputError, match='afile: exists and is not a folder but a file'):
        check_bag_output(afile, overwrite=True)
    with pytest.raises(OutputError, match=r'/proc/x: cannot write in /proc: '):
        check_bag_output(Path('/proc/x'))
    with pytest.raises(OutputError, match=r'is a file, not a folder'):
        check_bag_output(afile / 'sub')


def test_an_output_that_is_holds_or_lies_inside_an_input_is_refused(tmp_path):
    data = _folder(tmp_path, 'data', 'log.csv', 'm.yaml')
    for out, where in ((data, 'holds'), (tmp_path, 'holds'), (data / 'sub', 'lies inside')):
        with pytest.raises(OutputError, match=f'{where} .*an input of this command'):
            check_bag_output(out, overwrite=True, inputs=[data / 'log.csv', data])
    assert _tree(data) == {'log.csv': b'{}', 'm.yaml': b'{}'}


def test_a_sweep_folder_is_added_to_and_nothing_else_is_written_into(tmp_path):
    check_kind(_folder(tmp_path, 'sweep', 'sweep.db'), 'sweep', force=False)
    with pytest.raises(OutputError, match=r'holds a train run .*replaces only a sweep'):
        check_kind(_folder(tmp_path, 'run', 'run.json'), 'sweep', force=False)


def test_a_file_output_is_checked_for_its_suffix_its_place_and_what_is_there(tmp_path):
    png = ('.png', '.pdf')
    run = _folder(tmp_path, 'run', 'run.json', 'metrics.json')
    with pytest.raises(OutputError, match=r'metrics\.json: not a file type .*\.png'):
        check_file_output(run / 'metrics.json', force=True, suffixes=png)
    with pytest.raises(OutputError, match=r'holds a train run'):
        check_file_output(run / 'plot.png', force=True, suffixes=png)
    with pytest.raises(OutputError, match='is a folder; name a file'):
        check_file_output(_folder(tmp_path, 'x.png'), force=True, suffixes=png)
    existing = tmp_path / 'old.png'
    existing.write_bytes(b'png')
    with pytest.raises(OutputError, match=r'old\.png: exists; .*--force'):
        check_file_output(existing, suffixes=png)
    assert check_file_output(existing, force=True, suffixes=png) == existing


# -- the commands: refused before any work, the other result untouched --------------------------
def test_commands_never_replace_another_commands_result_even_with_force(tmp_path, capsys):
    bag = REPO / 'bags' / 'missing_bag_is_never_read'
    run = _folder(tmp_path, 'run', 'run.json', 'metrics.json')
    diagnosis = _folder(tmp_path, 'diagnosis', 'effects.json')
    before = {folder: _tree(folder) for folder in (run, diagnosis)}
    twin = str(REPO / 'config' / 'twin_default.yaml')
    commands = [
        (['demo', '--bag', str(bag), '--out', str(run), '--skip-training'], 'a demo'),
        (['diagnose', '--bag', str(bag), '--out', str(run), '--quiet'], 'a diagnosis'),
        (['simulate', '--config', twin, '--out', str(run), '--quiet'], 'a bag'),
        (['train', '--bag', str(bag), '--out', str(diagnosis), '--quiet'], 'a train run'),
    ]
    for argv, mine in commands:
        status, said = _cli(capsys, *argv, '--force')
        assert status == 2, said
        assert f'replaces only {mine}' in said, said
        assert 'Traceback' not in said
    assert {folder: _tree(folder) for folder in (run, diagnosis)} == before


def test_bag_outputs_that_are_files_or_unwritable_are_one_line(tmp_path, capsys):
    afile = tmp_path / 'afile'
    afile.write_text('mine')
    twin = str(REPO / 'config' / 'twin_default.yaml')
    for out, words in ((afile, 'not a folder but a file'), ('/proc/x', 'cannot write in /proc')):
        status, said = _cli(capsys, 'simulate', '--config', twin, '--out', str(out), '--force')
        assert (status, words in said, 'Traceback' in said) == (2, True, False), said
    assert afile.read_text() == 'mine'


def test_train_into_its_bag_is_refused(tmp_path, capsys):
    bag = _folder(tmp_path, 'bag', 'metadata.yaml', 'bag_0.mcap')
    status, said = _cli(capsys, 'train', '--bag', str(bag), '--out', str(bag / 'sub'), '--quiet')
    assert (status, 'lies inside' in said) == (2, True), said
    assert not (bag / 'sub').exists()


def test_force_never_deletes_a_file_the_manifest_does_not_list(tmp_path):
    out = tmp_path / 'eval'
    for _ in range(2):  # the second replaces the first: nothing foreign
        with result_folder(out, command='evaluate', force=True) as folder:
            (folder.work / 'metrics.json').write_text('{}')
    assert json.loads((out / MANIFEST_FILE).read_text())['entries'] == ['metrics.json']
    (out / 'my_notes.txt').write_text('precious')
    with pytest.raises(OutputError, match=r'my_notes\.txt, which its \.id_learning\.json'):
        check_output(out, force=True, kind='evaluation')
    assert (out / 'my_notes.txt').read_text() == 'precious'
    assert foreign_entries(out, 'evaluation') == ['my_notes.txt']


@pytest.mark.parametrize('force', [False, True])
def test_a_partial_that_is_not_ours_is_refused_and_kept(tmp_path, force):
    out = tmp_path / 'eval'
    (tmp_path / 'eval.partial').write_text('precious')
    with pytest.raises(OutputError, match=r'eval\.partial: exists and is not an incomplete'):
        check_output(out, force=force, kind='evaluation')
    (tmp_path / 'eval.partial').unlink()
    _folder(tmp_path, 'eval.partial', 'mine.txt')
    with pytest.raises(OutputError, match=r'a folder without incomplete\.json'):
        check_output(out, force=force, kind='evaluation')
    assert (tmp_path / 'eval.partial' / 'mine.txt').exists()
    assert incomplete_reason(out) is None


def _train_into(out: Path, *, force: bool = False, killed: bool = False) -> None:
    """Write a run to ``out`` as train does; ``killed``: stop half-way, keeping the partial."""
    with (
        contextlib.suppress(KeyboardInterrupt),
        result_folder(out, command='train', force=force) as folder,
    ):
        (folder.work / 'models').mkdir()
        if killed:
            folder.keep = True
            raise KeyboardInterrupt
        (folder.work / 'run.json').write_text('{}')


def test_force_never_deletes_a_user_file_inside_an_interrupted_partial(tmp_path):
    out = tmp_path / 'run'
    _train_into(out, killed=True)
    (partial_path(out) / 'notes.txt').write_text('precious')
    with pytest.raises(OutputError, match=r'run\.partial: .*holds notes\.txt.*never deletes'):
        _train_into(out, force=True)
    assert (partial_path(out) / 'notes.txt').read_text() == 'precious'
    (partial_path(out) / 'notes.txt').unlink()
    _train_into(out, force=True)
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_FILE, 'models', 'run.json']


def test_no_output_is_written_anywhere_inside_a_result_or_a_bag(tmp_path):
    with result_folder(tmp_path / 'run', command='train') as folder:
        (folder.work / 'run.json').write_text('{}')
        (folder.work / 'models' / 'mlp').mkdir(parents=True)
    bag = _folder(tmp_path, 'bag', 'metadata.yaml', 'bag_0.mcap')
    inside = {
        tmp_path / 'run' / 'models' / 'mlp': r'run, which holds a train run',
        bag: r'bag, which holds a bag',
        bag / 'deeper' / 'still': r'bag, which holds a bag',
    }
    for parent, holder in inside.items():
        for check in (
            lambda p: check_file_output(p / 'x.png'),
            lambda p: check_bag_output(p / 'inner', option='output:=PATH'),
            lambda p: check_output(p / 'inner', kind='evaluation'),
        ):
            with pytest.raises(OutputError, match=rf'(inner|x\.png): lies inside .*{holder}'):
                check(parent)
    assert not (bag / 'deeper').exists()
    assert not (bag / 'inner').exists()
    # A plot is held to more: never beside storage files, even without metadata.yaml.
    torn = _folder(tmp_path, 'torn', 'torn_0.mcap')
    with pytest.raises(OutputError, match=r'x\.png: lies inside .*torn, which holds a torn bag'):
        check_file_output(torn / 'x.png')


def test_a_users_folder_that_merely_holds_result_names_takes_outputs(tmp_path):
    mine = _folder(tmp_path, 'mine', 'metrics.json', 'summary.md', 'README')
    logs = _folder(tmp_path, 'logs', 'a.mcap', 'b.mcap')  # standalone MCAP files, no bag
    stray = _folder(tmp_path, 'home', 'run.json')
    (stray / 'work').mkdir()
    for parent in (mine, logs, stray / 'work'):
        assert check_output(parent / 'run1', kind='train') == parent / 'run1'
        assert check_bag_output(parent / 'rec') == parent / 'rec'
    (mine / 'plots').mkdir()
    assert check_file_output(mine / 'plots' / 'x.png') == mine / 'plots' / 'x.png'


def test_a_command_writes_its_steps_inside_its_own_partial_result(tmp_path):
    with result_folder(tmp_path / 'demo', command='demo') as folder:  # noqa: SIM117 (uses folder)
        with result_folder(folder.work / 'run', command='train') as inner:
            (inner.work / 'run.json').write_text('{}')
    assert (tmp_path / 'demo' / 'run' / 'run.json').is_file()


def test_a_dotdot_path_creates_no_folder_it_leaves(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert check_output(Path('rel/../rec'), kind='evaluation') == tmp_path / 'rec'
    assert not (tmp_path / 'rel').exists()
