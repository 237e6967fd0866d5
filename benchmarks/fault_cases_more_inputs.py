"""Fault cases of inputs checked by class where they enter: hyper-parameters of the wrong type,
out of range or given twice; one file or bag given twice; empty or unknown selections; a CSV row
with an extra cell; a bag folder with an unlisted storage file or another robot's joints; twin
settings rounded, aliased or beyond reason; a sweep storage in a missing folder.

Every case is refused (or said) before any long work: the catalogue runs in seconds.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from fault_kit import REPO, ROBOT_FILE, Case, Fixtures, Outcome, cli

__all__ = ['more_input_cases']

TWIN_FILE = REPO / 'config' / 'twin_default.yaml'
UR5_FILE = REPO / 'config' / 'ur5.yaml'


def more_input_cases(fx: Fixtures) -> Iterator[Case]:
    """Every case of this catalogue."""
    yield from _hyper_cases(fx)
    yield from _twice_cases(fx)
    yield from _selection_cases(fx)
    yield from _import_cases(fx)
    yield from _bag_cases(fx)
    yield from _twin_cases(fx)
    yield from _sweep_cases(fx)
    yield from _type_cases(fx)
    yield from _repeat_cases(fx)
    yield from _contradiction_cases(fx)
    yield from _metadata_cases(fx)


# -- helpers --------------------------------------------------------------------------------------
def _train(fx: Fixtures, name: str, *extra: str, expect: tuple[str, ...]) -> Outcome:
    return cli(['train', '--bag', str(fx.bag), '--models', 'mlp', '--out',
                str(fx.path(f'more_run_{name}')), '--quiet', '--force', *extra],
               expect=expect)  # fmt: skip


def _twin_file(fx: Fixtures, name: str, change: Callable[[dict], None]) -> Path:
    """The shipped twin config on the shipped robot, changed."""
    import yaml

    data = yaml.safe_load(TWIN_FILE.read_text())
    data['robot'] = str(ROBOT_FILE)
    change(data)
    path = fx.path(f'more_twin_{name}.yaml')
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _log(fx: Fixtures, name: str, extra_cell_row: int | None = None) -> tuple[Path, Path]:
    """A 300-row CSV of the clean recording and its mapping; one row may get an extra cell."""
    import yaml

    rec = fx.recording
    n = 300
    t = (rec.stamps_ns[:n] - rec.stamps_ns[0]) * 1e-9
    table = np.column_stack([t, rec.position[:n], rec.velocity[:n], rec.current[:n]])
    joints = range(len(rec.joints))
    header = ['t', *(f'q{j}' for j in joints), *(f'v{j}' for j in joints),
              *(f'i{j}' for j in joints)]  # fmt: skip
    rows = [','.join(repr(float(x)) for x in row) for row in table]
    if extra_cell_row is not None:
        rows[extra_cell_row] += ',1.0'
    log = fx.path(f'{name}.csv')
    log.write_text(','.join(header) + '\n' + '\n'.join(rows) + '\n')
    mapping = {
        'time': {'column': 't', 'unit': 's'},
        'joints': [
            {'name': name, 'position': {'column': f'q{j}', 'unit': 'rad'},
             'velocity': {'column': f'v{j}', 'unit': 'rad/s'},
             'current': {'column': f'i{j}', 'unit': 'A'}}
            for j, name in enumerate(rec.joints)
        ],
    }  # fmt: skip
    mapping_file = fx.path(f'{name}.yaml')
    mapping_file.write_text(yaml.safe_dump(mapping))
    return log, mapping_file


# -- hyper-parameters -----------------------------------------------------------------------------
def _hyper_cases(fx: Fixtures) -> Iterator[Case]:
    items = {
        'text for an int': ('mlp.batch_size=abc', ('mlp.batch_size', 'abc', 'integer')),
        'float for an int': ('mlp.width=32.7', ('mlp.width', '32.7', 'integer')),
        'bool for an int': ('mlp.width=true', ('mlp.width', 'True', 'integer')),
        'absurd width': ('mlp.width=1000000000', ('mlp.width', '1000000000', '4096')),
        'absurd epochs': ('mlp.max_epochs=10000000', ('mlp.max_epochs', '1e+06')),
        'text for a float': ('mlp.learning_rate=fast', ('mlp.learning_rate', 'fast', 'number')),
    }
    for name, (item, words) in items.items():
        yield Case(f'--hyper {name}', 'train',
                   lambda i=item, w=words, n=name: _train(fx, n.replace(' ', '_'), '--hyper', i,
                                                          expect=w))  # fmt: skip

    def twice() -> Outcome:
        return _train(fx, 'hyper_twice', '--hyper', 'mlp.width=64', '--hyper', 'mlp.width=8',
                      expect=('mlp.width', 'twice', '64', '8'))  # fmt: skip

    yield Case('--hyper key given twice', 'train', twice)

    def file_text() -> Outcome:
        path = fx.path('more_best_wide.yaml')
        path.write_text('mlp:\n  width: wide\n')
        return _train(fx, 'hyper_file_wide', '--hyper-file', str(path),
                      expect=('mlp.width', 'wide', 'integer'))  # fmt: skip

    yield Case('--hyper-file with text for an int', 'train', file_text)


# -- inputs given twice ---------------------------------------------------------------------------
def _twice_cases(fx: Fixtures) -> Iterator[Case]:
    def copy() -> Path:
        other = fx.path('more_bag_copy')
        if not other.exists():
            shutil.copytree(fx.bag, other)
        return other

    commands: dict[str, Callable[[Path], list[str]]] = {
        'train': lambda b: ['train', '--bag', str(fx.bag), '--bag', str(b), '--models', 'rnea_lq',
                            '--out', str(fx.path('more_run_twice')), '--quiet', '--force'],
        'diagnose': lambda b: ['diagnose', '--bag', str(fx.bag), '--bag', str(b), '--out',
                               str(fx.path('more_diag_twice')), '--quiet', '--force'],
        'sweep': lambda b: ['sweep', '--bag', str(fx.bag), '--bag', str(b), '--model', 'rnea_lq',
                            '--trials', '1', '--out', str(fx.path('more_sweep_twice'))],
    }  # fmt: skip
    for door, argv in commands.items():
        yield Case(f'{door}: the same bag twice', door,
                   lambda a=argv: cli(a(fx.bag), expect=('twice', str(fx.bag))))  # fmt: skip
        copied = ('identical', 'more_bag_copy')
        yield Case(f'{door}: a bag and its copy', door,
                   lambda a=argv, w=copied: cli(a(copy()), expect=w))  # fmt: skip

    def import_twice() -> Outcome:
        log, mapping = _log(fx, 'more_log_twice')
        return cli(['import', str(log), str(log), '--mapping', str(mapping), '--out',
                    str(fx.path('more_log_twice_bag'))],
                   expect=('twice', log.name))  # fmt: skip

    yield Case('import: the same log twice', 'import', import_twice)


# -- empty or unknown selections ------------------------------------------------------------------
def _selection_cases(fx: Fixtures) -> Iterator[Case]:
    def no_effects() -> Outcome:
        return cli(['diagnose', '--bag', str(fx.bag), '--effects', '', '--out',
                    str(fx.path('more_diag_empty')), '--quiet', '--force'],
                   expect=('--effects', 'no effect'))  # fmt: skip

    yield Case('diagnose --effects empty', 'diagnose', no_effects)

    def demo_models() -> Outcome:
        return cli(['demo', '--bag', str(fx.bag), '--skip-training', '--skip-diagnosis',
                    '--models', 'warp', '--out', str(fx.path('more_demo')), '--force'],
                   expect=('--models', '--skip-training'))  # fmt: skip

    yield Case('demo --skip-training with --models (an unknown one)', 'demo', demo_models)


# -- import ---------------------------------------------------------------------------------------
def _import_cases(fx: Fixtures) -> Iterator[Case]:
    def extra_cell() -> Outcome:
        log, mapping = _log(fx, 'more_log_extra', extra_cell_row=10)
        return cli(['import', str(log), '--mapping', str(mapping), '--out',
                    str(fx.path('more_log_extra_bag'))],
                   expect=(log.name, 'line 12', '20 cells', '1 more'))  # fmt: skip

    yield Case('import: a row with an extra cell', 'import', extra_cell)


# -- bags -----------------------------------------------------------------------------------------
def _bag_cases(fx: Fixtures) -> Iterator[Case]:
    def unlisted() -> Outcome:
        folder = fx.path('more_bag_unlisted')
        if not folder.exists():
            shutil.copytree(fx.bag, folder)
            shutil.copy(next(folder.glob('*.mcap')), folder / 'bag_1.mcap')
        return cli(['inspect', str(folder)], expect=(),
                   handled=('bag_1.mcap', 'not listed'))  # fmt: skip

    yield Case('bag folder with an unlisted bag_1.mcap', 'inspect', unlisted)

    def other_robot() -> Outcome:
        return cli(['inspect', str(fx.bag), '--robot', str(UR5_FILE)], expect=(),
                   handled=('joints do not match', 'limits were not checked'))  # fmt: skip

    yield Case("inspect against another robot's joints", 'inspect', other_robot)


# -- twin settings --------------------------------------------------------------------------------
def _twin_cases(fx: Fixtures) -> Iterator[Case]:
    def short() -> Outcome:
        return cli(['simulate', '--config', str(TWIN_FILE), '--duration', '5', '--out',
                    str(fx.path('more_twin_short')), '--quiet'], expect=(),
                   handled=('duration_s 5 s became', 'whole segment'))  # fmt: skip

    yield Case('simulate --duration shorter than a segment', 'simulate', short)

    def frequency(data: dict) -> None:
        data.setdefault('excitation', {})['base_frequency_hz'] = 50

    def delay(data: dict) -> None:
        data['effects']['signal_delay'] = {'enabled': True, 'delay_s': 10}

    settings = {
        'excitation above Nyquist': (frequency, ('base_frequency_hz', 'Nyquist', '62.5')),
        'signal delay of 10 s': (delay, ('delay_s', '10', '0.1')),
    }

    def refused(name: str, change: Callable[[dict], None], words: tuple[str, ...]) -> Outcome:
        config = _twin_file(fx, name.replace(' ', '_'), change)
        return cli(['simulate', '--config', str(config), '--out',
                    str(fx.path('more_twin_refused')), '--quiet'], expect=words)  # fmt: skip

    for name, (change, words) in settings.items():
        yield Case(f'twin config with {name}', 'simulate',
                   lambda n=name, c=change, w=words: refused(n, c, w))  # fmt: skip


# -- sweep storage --------------------------------------------------------------------------------
def _sweep_cases(fx: Fixtures) -> Iterator[Case]:
    def missing_folder() -> Outcome:
        return cli(['sweep', '--bag', str(fx.bag), '--model', 'rnea_lq', '--trials', '1',
                    '--storage', 'sqlite:////no/such/dir/x.db', '--out',
                    str(fx.path('more_sweep_storage'))],
                   expect=('/no/such/dir', 'does not exist'))  # fmt: skip

    yield Case('sweep storage in a missing folder', 'sweep', missing_folder)


# -- strings where numbers belong -----------------------------------------------------------------
def _type_cases(fx: Fixtures) -> Iterator[Case]:
    def twin(value: object) -> Outcome:
        def change(data: dict) -> None:
            data['effects']['viscous_friction']['coefficient'] = value

        config = _twin_file(fx, 'quoted', change)
        return cli(['simulate', '--config', str(config), '--out',
                    str(fx.path('more_twin_quoted_out')), '--quiet'],
                   expect=('coefficient', "'420'", 'without quotes'))  # fmt: skip

    yield Case("twin coefficient '420'", 'simulate', lambda: twin('420'))
    yield Case("twin coefficient ['420']*6", 'simulate', lambda: twin(['420'] * 6))

    def robot(key: str) -> Outcome:
        import yaml

        data = yaml.safe_load(ROBOT_FILE.read_text())
        data['urdf'] = str((ROBOT_FILE.parent / data['urdf']).resolve())
        if key == 'gear_ratio':
            data['drives']['gear_ratio'] = '205'
        else:
            data[key] = '10'
        path = fx.path(f'more_robot_{key}.yaml')
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        return _train(fx, f'robot_{key}', '--robot', str(path),
                      expect=(path.name, key, 'without quotes'))  # fmt: skip

    for key in ('gear_ratio', 'input_smoothing_hz'):
        yield Case(f'robot config {key} quoted', 'train', lambda k=key: robot(k))


# -- a value given twice in a list ----------------------------------------------------------------
def _repeat_cases(fx: Fixtures) -> Iterator[Case]:
    yield Case('train --models rnea_lq,rnea_lq', 'train',
               lambda: _train(fx, 'twice', '--models', 'rnea_lq,rnea_lq',
                              expect=('--models', 'rnea_lq given twice')))  # fmt: skip

    def effects() -> Outcome:
        return cli(['diagnose', '--bag', str(fx.bag), '--effects', 'cogging,cogging', '--out',
                    str(fx.path('more_diag_twice')), '--quiet', '--force'],
                   expect=('--effects', 'cogging given twice'))  # fmt: skip

    yield Case('diagnose --effects cogging,cogging', 'diagnose', effects)

    def study_name() -> Outcome:
        return cli(['sweep', '--bag', str(fx.bag), '--model', 'rnea_lq', '--study-name', '',
                    '--out', str(fx.path('more_sweep_name'))],
                   expect=('--study-name', 'must not be empty'))  # fmt: skip

    yield Case("sweep --study-name ''", 'sweep', study_name)


# -- contradictory options ------------------------------------------------------------------------
def _contradiction_cases(fx: Fixtures) -> Iterator[Case]:
    yield Case('train --split contiguous --split-seed 7', 'train',
               lambda: _train(fx, 'seed', '--split', 'contiguous', '--split-seed', '7',
                              expect=('--split-seed', '--split contiguous')))  # fmt: skip

    def demo(option: str, value: str) -> Outcome:
        return cli(['demo', '--bag', str(fx.bag), '--skip-training', option, value, '--out',
                    str(fx.path('more_demo_contradiction')), '--force'],
                   expect=(option, '--skip-training'))  # fmt: skip

    yield Case('demo --skip-training --train-seconds 5', 'demo',
               lambda: demo('--train-seconds', '5'))  # fmt: skip
    yield Case('demo --skip-training --online-seconds 1', 'demo',
               lambda: demo('--online-seconds', '1'))  # fmt: skip


# -- metadata.yaml contradicting the files --------------------------------------------------------
def _metadata_cases(fx: Fixtures) -> Iterator[Case]:
    def lying() -> Outcome:
        import yaml

        folder = fx.path('more_bag_metadata')
        if not folder.exists():
            shutil.copytree(fx.bag, folder)
            path = folder / 'metadata.yaml'
            data = yaml.safe_load(path.read_text())
            info = data['rosbag2_bagfile_information']
            info['message_count'] += 5
            info['duration']['nanoseconds'] = -1
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        return cli(['inspect', str(folder)], expect=(),
                   handled=('metadata: message_count', 'metadata: duration -1'))  # fmt: skip

    yield Case('inspect a bag whose metadata.yaml lies', 'inspect', lying)
