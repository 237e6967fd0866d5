"""Fault cases of values where they enter: duplicate YAML keys, NaN, inf and out-of-range numbers
in options, configs and node parameters, unbounded sizes and waits, bad topic names, and URDF
links no rigid body can be.

Each case is refused before any long work starts: the whole catalogue runs in seconds, the node
processes aside.
"""

from __future__ import annotations

import json
import math
import shutil
import sqlite3
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from fault_kit import REPO, ROBOT_FILE, Case, Fixtures, Outcome, cli, raises

__all__ = ['input_cases']

TWIN_FILE = REPO / 'config' / 'twin_default.yaml'
URDF_FILE = REPO / 'urdf' / 'mabi_max100.urdf'
#: link_3's inertia in the shipped URDF (150 kg).
LINK_3_INERTIA = 'ixx="4.9964" ixy="0" ixz="-1.0061333" iyy="7.07" iyz="0" izz="5.6256"'


def input_cases(fx: Fixtures) -> Iterator[Case]:
    """Every case of this catalogue."""
    yield from _duplicate_key_cases(fx)
    yield from _option_cases(fx)
    yield from _config_number_cases(fx)
    yield from _urdf_cases(fx)
    yield from _bound_cases(fx)
    yield from _node_parameter_cases(fx)


# -- helpers --------------------------------------------------------------------------------------
def _robot_file(fx: Fixtures, name: str, extra: str = '', urdf: str | None = None) -> Path:
    """The shipped robot config in a folder of its own, its URDF beside it, ``extra`` appended."""
    folder = fx.path(f'inputs_robot_{name}')
    folder.mkdir(exist_ok=True)
    (folder / 'arm.urdf').write_text(urdf if urdf is not None else URDF_FILE.read_text())
    text = ROBOT_FILE.read_text().replace('../urdf/mabi_max100.urdf', 'arm.urdf')
    path = folder / 'robot.yaml'
    path.write_text(text + extra)
    return path


def _twin_file(fx: Fixtures, name: str, change: Callable[[dict], None] | None = None,
               extra: str = '') -> Path:  # fmt: skip
    """The shipped twin config on the shipped robot, changed, ``extra`` appended."""
    import yaml

    data = yaml.safe_load(TWIN_FILE.read_text())
    data['robot'] = str(ROBOT_FILE)
    if change is not None:
        change(data)
    path = fx.path(f'inputs_twin_{name}.yaml')
    path.write_text(yaml.safe_dump(data, sort_keys=False) + extra)
    return path


def _train(fx: Fixtures, name: str, *extra: str, expect: tuple[str, ...]) -> Outcome:
    return cli(['train', '--bag', str(fx.bag), '--models', 'rnea_lq', '--out',
                str(fx.path(f'inputs_run_{name}')), '--quiet', '--force', *extra],
               expect=expect)  # fmt: skip


def _simulate(fx: Fixtures, config: Path, *extra: str, expect: tuple[str, ...]) -> Outcome:
    return cli(['simulate', '--config', str(config), '--out', str(fx.path(f'{config.stem}_bag')),
                '--quiet', *extra], expect=expect)  # fmt: skip


# -- duplicate keys -------------------------------------------------------------------------------
def _duplicate_key_cases(fx: Fixtures) -> Iterator[Case]:
    # The robot config names ipo_period_s once already: a second one would win silently.
    def robot() -> Outcome:
        path = _robot_file(fx, 'duplicate', extra='\nipo_period_s: 0.004\n')
        return _train(fx, 'duplicate', '--robot', str(path),
                      expect=('duplicate key', 'ipo_period_s', 'lines', str(path)))  # fmt: skip

    yield Case('robot config with a key given twice', 'train', robot)

    def twin() -> Outcome:
        path = _twin_file(fx, 'duplicate', extra='seed: 7\n')
        return _simulate(fx, path, expect=('duplicate key', 'seed', 'lines', path.name))

    yield Case('twin config with a key given twice', 'simulate', twin)

    def mapping() -> Outcome:
        path = fx.path('inputs_mapping_duplicate.yaml')
        path.write_text(
            'period_s: 0.008\njoints:\n  - name: joint_1\n'
            '    position: {column: q0, unit: rad}\n    position: {column: q1, unit: rad}\n'
        )
        return cli(['import', str(fx.path('no_log.csv')), '--mapping', str(path), '--out',
                    str(fx.path('inputs_mapping_bag'))],
                   expect=('duplicate key', 'position', 'lines 4 and 5', path.name))  # fmt: skip

    yield Case('import mapping with a key given twice', 'import', mapping)

    def hyper_file() -> Outcome:
        path = fx.path('inputs_best_duplicate.yaml')
        path.write_text('rnea_lq:\n  friction: viscous\n  friction: viscous_coulomb\n')
        return _train(fx, 'hyper_duplicate', '--hyper-file', str(path),
                      expect=('duplicate key', 'friction', 'lines 2 and 3'))  # fmt: skip

    yield Case('hyper-parameter file with a key given twice', 'train', hyper_file)

    def node_file() -> Outcome:
        from id_learning.errors import ConfigError
        from id_learning.nodes.params import PredictorNodeConfig, load_node_config

        path = fx.path('inputs_nodes_duplicate.yaml')
        path.write_text('predictor:\n  ros__parameters:\n    artifact: a\n'
                        '    range_margin: 0.1\n    range_margin: 0.5\n')  # fmt: skip
        return raises(lambda: load_node_config(path, 'predictor', PredictorNodeConfig),
                      ConfigError, ('duplicate key', 'range_margin', 'lines 4 and 5'))  # fmt: skip

    yield Case('node parameter file with a key given twice', 'node params', node_file)


# -- numeric command-line options -----------------------------------------------------------------
def _option_cases(fx: Fixtures) -> Iterator[Case]:
    bag, twin = str(fx.bag), str(TWIN_FILE)
    simulate = ['simulate', '--config', twin, '--out', str(fx.path('inputs_sim')), '--quiet']
    sweep = ['sweep', '--bag', bag, '--model', 'rnea_lq', '--out', str(fx.path('inputs_sweep'))]
    train = ['train', '--bag', bag, '--models', 'rnea_lq', '--out', str(fx.path('inputs_train')),
             '--quiet', '--force']  # fmt: skip
    table = [
        ('simulate duration nan', [*simulate, '--duration', 'nan'], ('--duration', 'nan')),
        ('simulate duration inf', [*simulate, '--duration', 'inf'], ('--duration', 'inf')),
        ('simulate duration negative', [*simulate, '--duration', '-5'], ('--duration', '-5')),
        ('simulate seed negative', [*simulate, '--seed', '-1'], ('--seed', '-1')),
        ('sweep trials zero', [*sweep, '--trials', '0'], ('--trials', '0')),
        ('sweep budget nan', [*sweep, '--max-seconds-per-trial', 'nan'],
         ('--max-seconds-per-trial', 'nan')),
        ('sweep storage timeout inf', [*sweep, '--storage-timeout', 'inf'],
         ('--storage-timeout', 'inf')),
        ('sweep seed beyond 32 bits', [*sweep, '--seed', str(2**40)], ('--seed', str(2**40))),
        ('train budget inf', [*train, '--max-seconds-per-model', 'inf'],
         ('--max-seconds-per-model', 'inf')),
        ('train split seed negative', [*train, '--split-seed', '-3'], ('--split-seed', '-3')),
        ('train hyper-parameter nan', [*train, '--hyper', 'rnea_lq.friction=.nan'],
         ('rnea_lq.friction', 'nan')),
        ('demo budget nan', ['demo', '--out', str(fx.path('inputs_demo')), '--train-seconds',
                             'nan'], ('--train-seconds', 'nan')),
    ]  # fmt: skip
    for name, argv, words in table:
        yield Case(f'option {name}', argv[0], lambda a=argv, w=words: cli(a, expect=w))


# -- numbers in config files ----------------------------------------------------------------------
def _config_number_cases(fx: Fixtures) -> Iterator[Case]:
    from id_learning.errors import ConfigError

    def excitation(key: str, value: object) -> Callable[[dict], None]:
        return lambda data: data['excitation'].update({key: value})

    twin_faults = {
        'duration inf': (excitation('duration_s', math.inf), ('excitation.duration_s', 'inf')),
        'harmonics 2.5': (excitation('harmonics', 2.5), ('excitation.harmonics', '2.5')),
        'rest nan': (excitation('rest_s', math.nan), ('excitation.rest_s', 'nan')),
        'shift start nan': (lambda data: data.update(shift_start_s=math.nan),
                            ('shift_start_s', 'nan')),
        'start time beyond int64': (lambda data: data.update(start_time_ns=2**70),
                                    ('start_time_ns',)),
    }  # fmt: skip
    for name, (change, words) in twin_faults.items():

        def twin(n: str = name, c: Callable[[dict], None] = change,
                 w: tuple[str, ...] = words) -> Outcome:  # fmt: skip
            return _simulate(fx, _twin_file(fx, n.replace(' ', '_'), c), expect=w)

        yield Case(f'twin config {name}', 'simulate', twin)

    robot_faults = {
        'locked joint nan': ({'locked_joints': {'gripper': math.nan}}, ('locked_joints', 'nan')),
        'topic with a space': ({'topics': {'joint_states': 'joint states'}},
                               ('topics.joint_states', 'joint states')),
        'label cut-off above nyquist': ({'lowpass_cutoff_hz': 80.0},
                                        ('lowpass_cutoff_hz', 'Nyquist', '62.5')),
    }  # fmt: skip
    for name, (changes, words) in robot_faults.items():

        def robot(n: str = name, c: dict = changes, w: tuple[str, ...] = words) -> Outcome:
            import yaml

            data = yaml.safe_load(ROBOT_FILE.read_text())
            data.update(urdf='arm.urdf', **c)
            path = _robot_file(fx, n.replace(' ', '_'))
            path.write_text(yaml.safe_dump(data))
            return _train(fx, n.replace(' ', '_'), '--robot', str(path), expect=w)

        yield Case(f'robot config {name}', 'train', robot)

    def preprocess(**settings: object) -> Callable[[], object]:
        from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset

        return lambda: prepare_dataset(fx.recording, fx.robot, PreprocessConfig(**settings))  # type: ignore[arg-type]

    preprocess_faults = {
        'label cut-off above nyquist': ({'cutoff_hz': (70.0,) * 6},
                                        ('cutoff_hz', '70 Hz', 'Nyquist', '62.5', '8 ms')),
        'input smoothing at nyquist': ({'input_smoothing_hz': (62.5,) * 6},
                                       ('input_smoothing_hz', 'Nyquist', '62.5')),
        'cut-off nan': ({'cutoff_hz': (math.nan,) * 6}, ('cutoff_hz[0]', 'nan')),
        'filter periods inf': ({'min_filter_periods': math.inf}, ('min_filter_periods', 'inf')),
    }  # fmt: skip
    for name, (settings, words) in preprocess_faults.items():
        yield Case(
            f'preprocessing {name}',
            'preprocess',
            lambda s=settings, w=words: raises(preprocess(**s), ConfigError, w),
        )


# -- URDF inertias --------------------------------------------------------------------------------
def _urdf_cases(fx: Fixtures) -> Iterator[Case]:
    text = URDF_FILE.read_text()
    faults = {
        'all-zero inertia under 150 kg': ('zero',
            'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"', ('link_3', 'all zero', 'arm.urdf')),
    }  # fmt: skip
    for name, (tag, inertia, words) in faults.items():

        def urdf(t: str = tag, i: str = inertia, w: tuple[str, ...] = words) -> Outcome:
            assert text.count(LINK_3_INERTIA) == 1
            path = _robot_file(fx, f'urdf_{t}', urdf=text.replace(LINK_3_INERTIA, i))
            return _train(fx, f'urdf_{t}', '--robot', str(path), expect=w)

        yield Case(f'urdf {name}', 'train', urdf)
    bent = {
        'inertia of a rod': ('rod', 'ixx="0" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"', 'thin rod'),
        'inertia against the triangle inequality': (
            'triangle', 'ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"', 'triangle inequality'),
    }  # fmt: skip
    for name, (tag, inertia, said) in bent.items():

        def warned(t: str = tag, i: str = inertia, w: str = said) -> Outcome:
            from id_learning.robot import check_urdf_inertials

            path = _robot_file(fx, f'urdf_{t}', urdf=text.replace(LINK_3_INERTIA, i))
            lines = check_urdf_inertials(path.parent / 'arm.urdf')
            if any('link_3' in line and w in line for line in lines):
                return Outcome('handled', lines[0][-300:])  # said, the robot still loads
            return Outcome('silently_accepted', f'nothing said: {lines}')

        yield Case(f'urdf {name}', 'robot config', warned)


# -- bounded sizes and waits ----------------------------------------------------------------------
def _bound_cases(fx: Fixtures) -> Iterator[Case]:
    words = ('--duration', '86400', '1000000000')
    yield Case(
        'simulate for 1e9 s',
        'simulate',
        lambda: _simulate(fx, TWIN_FILE, '--duration', '1e9', expect=words),
    )

    def locked_sqlite() -> Outcome:
        path = fx.path('inputs_locked.db')
        holder = sqlite3.connect(path, isolation_level=None)
        try:
            holder.execute('CREATE TABLE IF NOT EXISTS held (x)')
            holder.execute('BEGIN EXCLUSIVE')
            start = time.monotonic()
            outcome = cli(['sweep', '--bag', str(fx.bag), '--model', 'rnea_lq', '--trials', '1',
                           '--out', str(fx.path('inputs_sweep_locked')), '--storage',
                           f'sqlite:///{path}', '--storage-timeout', '1'],
                          expect=('inputs_locked.db', 'locked', 'within 1 s'))  # fmt: skip
            waited = time.monotonic() - start
        finally:
            holder.rollback()
            holder.close()
        if waited > 20:
            return Outcome('silently_accepted', f'waited {waited:.0f} s: {outcome.said}')
        return outcome

    yield Case('sweep on a locked SQLite file', 'sweep', locked_sqlite)

    def unreachable_postgres() -> Outcome:
        start = time.monotonic()
        storage = 'postgresql+psycopg://nobody@127.0.0.1:9/none'  # port 9: nothing listens
        outcome = cli(['sweep', '--bag', str(fx.bag), '--model', 'rnea_lq', '--trials', '1',
                       '--out', str(fx.path('inputs_sweep_pg')), '--storage', storage,
                       '--storage-timeout', '2'], expect=('127.0.0.1:9',))  # fmt: skip
        waited = time.monotonic() - start
        if waited > 30:
            return Outcome('silently_accepted', f'waited {waited:.0f} s: {outcome.said}')
        return outcome

    yield Case('sweep on an unreachable PostgreSQL server', 'sweep', unreachable_postgres)

    def nested_model_json(text: str) -> Outcome:
        from id_learning.errors import CheckpointError
        from id_learning.predictor import FeedForwardPredictor

        if fx.run_dir is None:
            return Outcome('handled', 'skipped: no run')
        folder = fx.path(f'inputs_artifact_nested_{len(text)}')
        shutil.copytree(fx.artifact, folder, dirs_exist_ok=True)
        (folder / 'model.json').write_text(text)
        return raises(lambda: FeedForwardPredictor.from_artifact(folder, fx.robot),
                      CheckpointError, (str(folder / 'model.json'), 'nested deeper'))  # fmt: skip

    deep = '[' * 200_000 + ']' * 200_000
    yield Case('artifact model.json nested 200000 deep', 'predictor',
               lambda: nested_model_json(deep))  # fmt: skip

    def nested_inside_an_artifact() -> Outcome:
        if fx.run_dir is None:
            return Outcome('handled', 'skipped: no run')
        data = json.loads((fx.artifact / 'model.json').read_text())
        inner: dict = {}
        data['fitted']['extra'] = inner
        for _ in range(900):  # within the JSON parser's stack, beyond any model.json
            inner['x'] = {}
            inner = inner['x']
        return nested_model_json(json.dumps(data))

    yield Case('artifact model.json with a field nested 900 deep', 'predictor',
               nested_inside_an_artifact)  # fmt: skip


# -- node parameters ------------------------------------------------------------------------------
def _node_parameter_cases(fx: Fixtures) -> Iterator[Case]:
    from id_learning.errors import ConfigError
    from id_learning.nodes.params import (
        PredictorNodeConfig,
        RecorderConfig,
        ReplayConfig,
        config_from_mapping,
        validate_change,
    )

    nan, inf = math.nan, math.inf
    # What a node reads at start (read_snapshot names the node the same way).
    table: list[tuple[str, type, dict[str, object], tuple[str, ...]]] = [
        ('predictor range_margin nan', PredictorNodeConfig, {'range_margin': nan},
         ('node predictor', 'range_margin', 'nan')),
        ('predictor torque_limit_scale inf', PredictorNodeConfig, {'torque_limit_scale': inf},
         ('torque_limit_scale', 'inf', '[1e-06, 1]')),
        ('predictor max_age_s -inf', PredictorNodeConfig, {'max_age_s': -inf},
         ('max_age_s', '-inf')),
        ('predictor input_depth beyond a million', PredictorNodeConfig, {'input_depth': 10**7},
         ('input_depth', '10000000')),
        ('predictor input_topic with a space', PredictorNodeConfig,
         {'input_topic': 'ref erence'}, ('input_topic', 'ref erence')),
        ('predictor output_topic starting with a digit', PredictorNodeConfig,
         {'output_topic': '1tau'}, ('output_topic', '1tau', 'digit')),
        ('predictor command_topic with //', PredictorNodeConfig, {'command_topic': 'a//b'},
         ('command_topic', 'a//b')),
        ('predictor measured_topic unknown substitution', PredictorNodeConfig,
         {'measured_topic': '{robot}/currents'}, ('measured_topic', '{robot}')),
        ('predictor unknown executor', PredictorNodeConfig, {'executor': 'threads'},
         ('executor', 'threads')),
        ('recorder topic with a space', RecorderConfig,
         {'topics': ['/joint_states', '/motor currents']}, ('topics', '/motor currents')),
        ('recorder flush period nan', RecorderConfig, {'flush_period_s': nan},
         ('flush_period_s', 'nan')),
        ('replay rate nan', ReplayConfig, {'bag': 'b', 'rate': nan}, ('rate', 'nan')),
        ('replay reference_topic with a misplaced tilde', ReplayConfig,
         {'bag': 'b', 'reference_topic': 'ref~'}, ('reference_topic', 'ref~')),
        ('replay start offset inf', ReplayConfig, {'bag': 'b', 'start_offset_s': inf},
         ('start_offset_s', 'inf')),
    ]  # fmt: skip

    def refused(name: str, cls: type, values: dict[str, object],
                words: tuple[str, ...]) -> Outcome:  # fmt: skip
        node = name.split(' ', maxsplit=1)[0]
        required = {'artifact': 'a'} if cls is PredictorNodeConfig else {}
        return raises(lambda: config_from_mapping(cls, {**required, **values}, f'node {node}'),
                      ConfigError, words)  # fmt: skip

    for name, cls, values, words in table:
        yield Case(
            f'node parameter {name}',
            'node params',
            lambda n=name, c=cls, v=values, w=words: refused(n, c, v, w),
        )

    def runtime_change() -> Outcome:
        changed, reason = validate_change(PredictorNodeConfig(artifact='a'), {'range_margin': nan})
        if changed is not None:
            return Outcome('silently_accepted', f'range_margin {changed.range_margin} accepted')
        clear = 'range_margin' in reason and 'nan' in reason
        return Outcome('clear_error' if clear else 'silently_accepted', reason)

    yield Case('node parameter range_margin set to nan at runtime', 'node params', runtime_change)
    yield from _node_process_cases(fx)


def _node_process_cases(fx: Fixtures) -> Iterator[Case]:
    """The same refusals at a node's door: the process exits 2 and says why, no traceback."""
    try:
        import rclpy  # noqa: F401 -- the nodes need ROS 2
    except ImportError:
        return
    from fault_cases_nodes import _refused

    if fx.run_dir is None:
        return
    logs = fx.path('inputs_node_logs')
    cases = {
        'predictor with range_margin nan': ({'range_margin': '.nan'}, ('range_margin', 'nan')),
        'predictor with an invalid input topic': ({'input_topic': 'ref~erence'},
                                                  ('input_topic', 'ref~erence')),
    }  # fmt: skip

    def refused(name: str, parameters: dict[str, object], words: tuple[str, ...]) -> Outcome:
        folder = logs / name.replace(' ', '_')
        return _refused(folder, 'predictor', {'artifact': str(fx.artifact), **parameters}, words)

    for name, (parameters, words) in cases.items():
        yield Case(name, 'predictor', lambda n=name, p=parameters, w=words: refused(n, p, w))
