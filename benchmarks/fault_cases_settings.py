"""Fault cases of settings and models: CLI, artifacts, the predictor core, configs, other doors."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from fault_kit import (
    REPO,
    ROBOT_FILE,
    Case,
    Fixtures,
    Outcome,
    broken_bag,
    cli,
    raises,
    with_value,
)


# -- cases: command-line settings -----------------------------------------------------------------
def cli_cases(fx: Fixtures) -> Iterator[Case]:
    bag = str(fx.bag)
    out = str(fx.path('cli_run'))
    base = ['train', '--bag', bag, '--out', out, '--quiet', '--force']
    table = [
        ('unknown model kind', [*base, '--models', 'delan2'], ('delan2',)),
        ('unknown hyper-parameter', [*base, '--models', 'mlp', '--hyper', 'mlp.widht=3'],
         ('widht',)),
        ('negative learning rate', [*base, '--models', 'mlp', '--hyper',
                                    'mlp.learning_rate=-1'], ('learning_rate',)),
        ('hyper without kind', [*base, '--hyper', 'width=3'], ('width',)),
        ('robot file absent', [*base, '--robot', str(fx.path('nope.yaml'))], ('nope.yaml',)),
        ('target unknown', [*base, '--target', 'wrist'], ('wrist',)),
        ('cuda without a gpu', [*base, '--models', 'mlp', '--device', 'cuda'], ('cuda',)),
        ('budget negative', [*base, '--models', 'mlp', '--max-seconds-per-model', '-5'],
         ('max_seconds',)),
        ('study table absent', [*base, '--models', 'rnea_lq', '--study-table',
                                str(fx.path('t1.json'))], ('t1.json',)),
        ('simulate config absent', ['simulate', '--config', str(fx.path('twin.yaml')), '--out',
                                    str(fx.path('sim'))], ('twin.yaml',)),
        ('inspect absent bag', ['inspect', str(fx.path('nothing'))], ('nothing',)),
        ('recover absent bag', ['bag', 'recover', str(fx.path('nothing'))], ('nothing',)),
        ('evaluate absent run', ['evaluate', '--run', str(fx.path('norun')), '--bag', bag,
                                 '--out', str(fx.path('ev'))], ('norun',)),
    ]  # fmt: skip
    for name, argv, words in table:
        yield Case(f'cli {name}', argv[0], lambda argv=argv, words=words: cli(argv, expect=words))

    def existing_run() -> Outcome:
        if fx.run_dir is None:
            return Outcome('handled', 'skipped: no run')
        before = {p: p.read_bytes() for p in fx.run_dir.rglob('*') if p.is_file()}
        outcome = cli(['train', '--bag', bag, '--models', 'rnea_lq', '--out', str(fx.run_dir),
                       '--quiet'], expect=('--force',))  # fmt: skip
        after = {p: p.read_bytes() for p in fx.run_dir.rglob('*') if p.is_file()}
        return outcome if after == before else Outcome('data_lost', 'the old run changed')

    yield Case('train into an existing run', 'train', existing_run)


# -- cases: artifacts -----------------------------------------------------------------------------
def artifact_cases(fx: Fixtures) -> Iterator[Case]:
    if fx.run_dir is None:
        return

    def copy(name: str) -> Path:
        target = fx.path(f'artifact_{name}')
        shutil.copytree(fx.artifact, target)
        return target

    def evaluate(folder: Path, words: tuple[str, ...]) -> Outcome:
        from id_learning.errors import CheckpointError
        from id_learning.predictor import FeedForwardPredictor

        return raises(
            lambda: FeedForwardPredictor.from_artifact(folder, fx.robot), CheckpointError, words
        )

    def edit_json(name: str, change: Callable[[dict], None], words: tuple[str, ...]) -> Outcome:
        folder = copy(name)
        meta = folder / 'model.json'
        data = json.loads(meta.read_text())
        change(data)
        meta.write_text(json.dumps(data))
        return evaluate(folder, words)

    def nan_scaler(data: dict) -> None:
        data['target_scaler']['low'][2] = float('nan')

    def units(data: dict) -> None:
        data['units']['tau'] = 'kN*m'

    def joints(data: dict) -> None:
        data['robot']['joints'] = list(reversed(data['robot']['joints']))

    def hyper(data: dict) -> None:
        friction = data['hyperparameters']['friction']
        data['hyperparameters']['friction'] = (
            'viscous' if friction != 'viscous' else 'viscous_coulomb'
        )

    def fitted_value(data: dict) -> None:
        fitted = data['fitted']
        key = next(k for k, v in fitted.items() if isinstance(v, list) and v)
        fitted[key] = fitted[key][:-1] if len(fitted[key]) > 1 else [0.0]

    edits = {
        'nan in a scaler': (nan_scaler, ('target_scaler', 'nan')),
        'other units': (units, ('units',)),
        'joints reversed': (joints, ('joints',)),
        'hyper-parameter changed': (hyper, ('artifact_sha256',)),
        'fitted array shortened': (fitted_value, ('model.json',)),
    }
    for name, (change, words) in edits.items():
        yield Case(f'artifact {name}', 'predictor', lambda n=name, c=change, w=words:
                   edit_json(n.replace(' ', '_'), c, w))  # fmt: skip

    def weights(kind: str) -> Outcome:
        folder = copy(f'weights_{kind}')
        path = folder / 'weights.safetensors'
        data = bytearray(path.read_bytes())
        if kind == 'flipped':
            data[-3] ^= 0xFF
            path.write_bytes(bytes(data))
        elif kind == 'truncated':
            path.write_bytes(bytes(data[: len(data) // 2]))
        else:
            path.unlink()
        return evaluate(folder, ('weights.safetensors',))

    for kind in ('flipped', 'truncated', 'missing'):
        yield Case(f'artifact weights {kind}', 'predictor', lambda kind=kind: weights(kind))

    def nan_weight() -> Outcome:
        """A NaN written into the weights file (its hash left as it was)."""
        from safetensors.numpy import load_file, save_file

        folder = copy('weights_nan')
        path = folder / 'weights.safetensors'
        tensors = {name: value.copy() for name, value in load_file(str(path)).items()}
        name = sorted(tensors)[0]
        tensors[name].flat[0] = np.nan
        save_file(tensors, str(path))
        return evaluate(folder, ('non-finite', name))

    yield Case('artifact with a NaN weight', 'predictor', nan_weight)

    def not_json() -> Outcome:
        folder = copy('not_json')
        (folder / 'model.json').write_text('weights: pickled\n')
        return evaluate(folder, ('not valid JSON',))

    yield Case('artifact model.json not JSON', 'predictor', not_json)

    def other_robot() -> Outcome:
        from id_learning.errors import CheckpointError
        from id_learning.predictor import FeedForwardPredictor
        from id_learning.robot import load_robot_config

        ur5 = load_robot_config(REPO / 'config/ur5.yaml')
        return raises(lambda: FeedForwardPredictor.from_artifact(fx.artifact, ur5),
                      CheckpointError, ('joints',))  # fmt: skip

    yield Case('artifact for another robot', 'predictor', other_robot)

    def evaluate_nan() -> Outcome:
        folder = copy('eval_nan')
        meta = folder / 'model.json'
        data = json.loads(meta.read_text())
        nan_scaler(data)
        meta.write_text(json.dumps(data))
        run = fx.path('run_eval_nan')
        shutil.copytree(fx.run_dir, run)  # type: ignore[arg-type]
        shutil.rmtree(run / 'models' / 'rnea_lq')
        shutil.copytree(folder, run / 'models' / 'rnea_lq')
        return cli(['evaluate', '--run', str(run), '--bag', str(fx.bag), '--out',
                    str(fx.path('eval_nan_out'))], expect=('nan',))  # fmt: skip

    yield Case('evaluate with a NaN in an artifact', 'evaluate', evaluate_nan)


# -- cases: the predictor's core ------------------------------------------------------------------
def predictor_cases(fx: Fixtures) -> Iterator[Case]:
    if fx.run_dir is None:
        return
    from id_learning.predictor import FeedForwardPredictor, ReferenceSample

    rec = fx.recording
    joints = tuple(rec.joints)
    period = 8_000_000

    def run(change: Callable[[dict], dict]) -> Outcome:
        predictor = FeedForwardPredictor.from_artifact(fx.artifact, fx.robot)
        start = 200
        for k in range(start, start + 5):
            sample = ReferenceSample(int(rec.stamps_ns[k]), joints, rec.position[k],
                                     rec.velocity[k], np.zeros(6))  # fmt: skip
            predictor.step(sample, k * period)
        k = start + 5
        fields = {'stamp_ns': int(rec.stamps_ns[k]), 'names': joints, 'q': rec.position[k].copy(),
                  'v': rec.velocity[k].copy(), 'a': np.zeros(6)}  # fmt: skip
        try:
            result = predictor.step(ReferenceSample(**change(fields)), k * period)
        except Exception as error:
            return Outcome('traceback', f'{type(error).__name__}: {error}')
        if result.tau is not None:
            return Outcome('silently_accepted', f'tau {np.round(result.tau, 1).tolist()}')
        k += 1
        after = predictor.step(
            ReferenceSample(int(rec.stamps_ns[k]), joints, rec.position[k], rec.velocity[k],
                            np.zeros(6)), k * period)  # fmt: skip
        if after.tau is None or not np.isfinite(after.tau).all():
            return Outcome('silently_accepted', 'no torque after valid input returned')
        return Outcome('handled', f'{result.reject.value}: {result.detail}')  # type: ignore[union-attr]

    def set_q(value: float, joint: int = 0) -> Callable[[dict], dict]:
        def change(fields: dict) -> dict:
            fields['q'][joint] = value
            return fields

        return change

    def set_v(value: float, joint: int = 0) -> Callable[[dict], dict]:
        def change(fields: dict) -> dict:
            fields['v'][joint] = value
            return fields

        return change

    limit = fx.robot.limits.velocity[0]
    changes: dict[str, Callable[[dict], dict]] = {
        'nan position': set_q(np.nan),
        'inf velocity': set_v(np.inf, 3),
        '1e300 position': set_q(1e300),
        '-1e300 position': set_q(-1e300, 2),
        '6x velocity': set_v(6 * limit),
        'degrees position': lambda f: {**f, 'q': np.degrees(f['q']) + 100.0},
        'acceleration 1e4': lambda f: {**f, 'a': np.full(6, 1e4)},
        'five joints': lambda f: {**f, 'names': joints[:5], 'q': f['q'][:5], 'v': f['v'][:5],
                                  'a': f['a'][:5]},
        'renamed joint': lambda f: {**f, 'names': (*joints[:5], 'joint_7')},
        'stamp backwards': lambda f: {**f, 'stamp_ns': int(rec.stamps_ns[190])},
        'stamp repeated': lambda f: {**f, 'stamp_ns': int(rec.stamps_ns[204])},
        'short velocity': lambda f: {**f, 'v': f['v'][:3]},
    }  # fmt: skip
    for name, change in changes.items():
        yield Case(f'predictor {name}', 'predictor', lambda change=change: run(change))


# -- cases: robot and twin configs ---------------------------------------------------------------
def config_cases(fx: Fixtures) -> Iterator[Case]:
    import yaml

    robot_text = ROBOT_FILE.read_text()
    urdf_text = (REPO / 'urdf' / 'mabi_max100.urdf').read_text()

    def robot_variant(name: str, change: Callable[[dict], None], urdf: str | None = None) -> Path:
        data = yaml.safe_load(robot_text)
        folder = fx.path(f'robot_{name}')
        folder.mkdir(exist_ok=True)
        urdf_path = folder / 'arm.urdf'
        urdf_path.write_text(urdf if urdf is not None else urdf_text)
        data['urdf'] = 'arm.urdf'
        change(data)
        path = folder / 'robot.yaml'
        path.write_text(yaml.safe_dump(data))
        return path

    def train_with(robot: Path, words: tuple[str, ...]) -> Outcome:
        return cli(['train', '--bag', str(fx.bag), '--robot', str(robot), '--models', 'rnea_lq',
                    '--out', str(fx.path(f'run_{robot.parent.name}')), '--quiet', '--force'],
                   expect=words)  # fmt: skip

    def set_limit(key: str, index: int, value: float) -> Callable[[dict], None]:
        def change(data: dict) -> None:
            data['limits'][key][index] = value

        return change

    def drop(key: str) -> Callable[[dict], None]:
        def change(data: dict) -> None:
            del data[key]

        return change

    def setter(key: str, value: object) -> Callable[[dict], None]:
        def change(data: dict) -> None:
            data[key] = value

        return change

    def drive(key: str, index: int, value: float) -> Callable[[dict], None]:
        def change(data: dict) -> None:
            data['drives'][key][index] = value

        return change

    robot_faults = {
        'limits reversed': (set_limit('position_lower', 1, 2.0), ('position',)),
        'negative velocity limit': (set_limit('velocity', 2, -1.0), ('velocity',)),
        'nan torque limit': (set_limit('torque', 0, float('nan')), ('torque',)),
        'five torque limits': (lambda d: d['limits'].update(torque=d['limits']['torque'][:5]),
                               ('torque',)),
        'no joints key': (drop('joints'), ('joints',)),
        'joint not in the urdf': (lambda d: d['joints'].__setitem__(3, 'elbow_roll'),
                                  ('elbow_roll',)),
        'zero gear ratio': (drive('gear_ratio', 0, 0.0), ('gear_ratio',)),
        'negative torque constant': (drive('torque_constant', 1, -2.0), ('torque_constant',)),
        'ipo period zero': (setter('ipo_period_s', 0.0), ('ipo_period_s',)),
        'unknown key': (setter('gear_ratio', [1.0] * 6), ('gear_ratio',)),
        'urdf absent': (setter('urdf', 'missing.urdf'), ('missing.urdf',)),
    }  # fmt: skip
    for name, (change, words) in robot_faults.items():
        yield Case(f'robot config {name}', 'train', lambda n=name, c=change, w=words:
                   train_with(robot_variant(n.replace(' ', '_'), c), w))  # fmt: skip

    urdf_faults = {
        'negative mass': (urdf_text.replace('<mass value="320"/>', '<mass value="-320"/>', 1),
                          ('mass',)),
        'not xml': ('<robot name="x"><link', ('urdf',)),
    }  # fmt: skip
    for name, (text, words) in urdf_faults.items():

        def run(n: str = name, t: str = text, w: tuple[str, ...] = words) -> Outcome:
            return train_with(robot_variant(f'urdf_{n.replace(" ", "_")}', lambda d: None, t), w)

        yield Case(f'urdf {name}', 'train', run)

    twin_text = (REPO / 'config' / 'twin_default.yaml').read_text()

    def twin_variant(name: str, change: Callable[[dict], None], words: tuple[str, ...]) -> Outcome:
        data = yaml.safe_load(twin_text)
        data['robot'] = str(ROBOT_FILE)
        change(data)
        path = fx.path(f'twin_{name}.yaml')
        path.write_text(yaml.safe_dump(data))
        return cli(['simulate', '--config', str(path), '--out', str(fx.path(f'sim_{name}')),
                    '--quiet', '--duration', '30'], expect=words)  # fmt: skip

    def effect(name: str, key: str, value: object) -> Callable[[dict], None]:
        def change(data: dict) -> None:
            data['effects'][name][key] = value

        return change

    twin_faults = {
        'unknown effect': (lambda d: d['effects'].update(backlash={'enabled': True}),
                           ('backlash',)),
        'negative friction': (effect('viscous_friction', 'coefficient', [-1.0] * 6),
                              ('coefficient',)),
        'five friction values': (effect('coulomb_friction', 'level', [1.0] * 5), ('level',)),
        'negative duration': (lambda d: d['excitation'].update(duration_s=-5.0), ('duration_s',)),
        'position fraction 2': (lambda d: d['excitation'].update(position_fraction=2.0),
                                ('position_fraction',)),
        'negative noise': (lambda d: d['measurement'].update(current_noise_std_a=[-0.1] * 6),
                           ('current_noise_std_a',)),
    }  # fmt: skip
    for name, (change, words) in twin_faults.items():
        yield Case(f'twin config {name}', 'simulate', lambda n=name, c=change, w=words:
                   twin_variant(n.replace(' ', '_'), c, w))  # fmt: skip


# -- cases: diagnose, evaluate and sweep on bad input ---------------------------------------------
def other_door_cases(fx: Fixtures) -> Iterator[Case]:
    rec = fx.recording

    def nan_bag() -> Path:
        name = 'door_nan'
        if not fx.path(name).exists():
            broken_bag(fx, name, position=with_value(rec.position, 70, 3, np.nan))
        return fx.path(name)

    yield Case('diagnose on a NaN bag', 'diagnose', lambda: cli(
        ['diagnose', '--bag', str(nan_bag()), '--out', str(fx.path('diag_nan')), '--quiet'],
        expect=('sample 70', 'joint_4')))  # fmt: skip
    yield Case('sweep on a NaN bag', 'sweep', lambda: cli(
        ['sweep', '--bag', str(nan_bag()), '--model', 'rnea_lq', '--trials', '1', '--out',
         str(fx.path('sweep_nan'))], expect=('sample 70', 'joint_4')))  # fmt: skip
    yield Case('sweep with an unknown storage', 'sweep', lambda: cli(
        ['sweep', '--bag', str(fx.bag), '--model', 'rnea_lq', '--trials', '1', '--out',
         str(fx.path('sweep_url')), '--storage', 'mongodb://nowhere/x'],
        expect=('mongodb',)))  # fmt: skip
    yield Case('sweep of an unknown kind', 'sweep', lambda: cli(
        ['sweep', '--bag', str(fx.bag), '--model', 'delan3', '--trials', '1', '--out',
         str(fx.path('sweep_kind'))], expect=('delan3',)))  # fmt: skip
    if fx.run_dir is not None:
        yield Case('evaluate on a NaN bag', 'evaluate', lambda: cli(
            ['evaluate', '--run', str(fx.run_dir), '--bag', str(nan_bag()), '--out',
             str(fx.path('eval_bag_nan'))], expect=('sample 70', 'joint_4')))  # fmt: skip

        def evaluate_other_robot() -> Outcome:
            return cli(['evaluate', '--run', str(fx.run_dir), '--bag', str(fx.bag), '--robot',
                        str(REPO / 'config/ur5.yaml'), '--out', str(fx.path('eval_ur5'))],
                       expect=('joint',))  # fmt: skip

        yield Case('evaluate with another robot', 'evaluate', evaluate_other_robot)

    def inspect_garbage() -> Outcome:
        target = fx.path('inspect_garbage')
        shutil.copytree(fx.bag, target)
        (mcap,) = target.glob('*.mcap')
        mcap.write_bytes(b'\x00' * 64)
        return cli(['inspect', str(target)], expect=('inspect_garbage', 'cannot open bag'))

    yield Case('inspect a file that is not MCAP', 'inspect', inspect_garbage)

    def inspect_nan() -> Outcome:
        outcome = cli(['inspect', str(nan_bag())], expect=())
        # inspect never refuses: it must list the problem instead.
        if outcome.kind == 'silently_accepted' and 'non-finite' in outcome.said:
            return Outcome('handled', outcome.said)
        return outcome

    yield Case('inspect a NaN bag', 'inspect', inspect_nan)
