"""Fault injection: bad input at the offline doors and the predictor core, outcomes classified.

    python benchmarks/faults.py [--out DIR] [--only SUBSTRING]

Builds a short twin recording, a fitted artifact and an import log, then breaks them one way at a
time (bad values, wrong types and units, truncated and corrupted bags and artifacts) and feeds
each to the door a user would: the ``id-learning`` commands (run in-process through the CLI's
``main``, exactly as the shell runs them), the replay's plan, ``bag recover`` and the predictor's
core. Each case is classified:

- ``clear_error``: refused (exit status != 0, or the documented exception) with a message that
  names what is wrong (the case's expected words);
- ``handled``: accepted on purpose and said so (a reordered joint list, a trimmed tail with a
  warning, a sample refused online while the stream goes on);
- ``silently_accepted``: exit 0 or a torque, with nothing said;
- ``traceback``: an exception the door did not turn into a message;
- ``data_lost``: a recovery that kept less than it should (less than 40 % of a bag cut at half).

Prints a table, then one JSON line with ``cases``, ``clear_error``, ``handled``,
``silently_accepted``, ``traceback``, ``data_lost`` and the cases that are not clear errors or
handled. Doors: train, evaluate, diagnose, sweep, import, inspect, simulate, bag recover, the
robot and twin configs and the URDF, the replay's plan and the predictor's core. Not yet covered
(issue 17): the nodes as processes (a killed recorder, overload), the online check.
``test/test_faults.py`` runs every case in the test suite (11 s here).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import shutil
import sys
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ROBOT_FILE = REPO / 'config' / 'mabi_max100.yaml'
KINDS = ('clear_error', 'handled', 'silently_accepted', 'traceback', 'data_lost')


@dataclass(frozen=True)
class Outcome:
    """How one case ended: its class and what the door said."""

    kind: str
    said: str


@dataclass(frozen=True)
class Case:
    """One fault: a name, the door it goes through, and how to run it."""

    name: str
    door: str
    run: Callable[[], Outcome]


def cli(argv: list[str], *, expect: tuple[str, ...], handled: tuple[str, ...] = ()) -> Outcome:
    """Run ``id-learning argv`` in-process; a refusal must name every word in ``expect``."""
    from id_learning.cli.main import main

    err, out = io.StringIO(), io.StringIO()
    log = logging.StreamHandler(err)  # warnings go to the stderr of this case
    log.setLevel(logging.WARNING)
    logging.getLogger().addHandler(log)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            status = main(argv)
    except SystemExit as exit_:  # argparse refuses bad flags with exit 2
        status = exit_.code if isinstance(exit_.code, int) else 1
    except Exception as error:  # what the fault suite is there to find
        return Outcome('traceback', f'{type(error).__name__}: {error}')
    finally:
        logging.getLogger().removeHandler(log)
    said = (err.getvalue() + out.getvalue()).strip()
    if status != 0:
        missing = [word for word in expect if word.lower() not in said.lower()]
        return Outcome('clear_error' if not missing else 'silently_accepted', said[-400:])
    if handled and all(word.lower() in said.lower() for word in handled):
        return Outcome('handled', said[-400:])
    return Outcome('silently_accepted', said[-400:])


def raises(run: Callable[[], object], error: type[Exception], expect: tuple[str, ...]) -> Outcome:
    """A core call that must raise ``error`` naming every word in ``expect``."""
    try:
        run()
    except error as refused:
        text = str(refused)
        missing = [word for word in expect if word.lower() not in text.lower()]
        return Outcome('clear_error' if not missing else 'silently_accepted', text[-400:])
    except Exception as other:
        return Outcome('traceback', f'{type(other).__name__}: {other}')
    return Outcome('silently_accepted', 'accepted')


# -- fixtures -------------------------------------------------------------------------------------
@dataclass
class Fixtures:
    """What the cases break: a clean recording and bag, an artifact, an import log."""

    root: Path
    robot: object
    recording: object
    bag: Path
    run_dir: Path | None = None

    @property
    def artifact(self) -> Path:
        assert self.run_dir is not None
        return self.run_dir / 'models' / 'rnea_lq'

    def path(self, name: str) -> Path:
        return self.root / name


def build_fixtures(root: Path, *, train: bool) -> Fixtures:
    from id_learning.dataset.recording import load_recording, write_recording
    from id_learning.robot import load_robot_config
    from id_learning.training import train_run
    from id_learning.twin import load_twin_config, simulate, write_twin_output

    robot = load_robot_config(ROBOT_FILE)
    config = load_twin_config(REPO / 'config/twin_default.yaml', {'seed': 91})
    config = replace(config, excitation=replace(config.excitation, duration_s=26.0))
    twin = write_twin_output(simulate(config), config, root / 'twin')
    recording = load_recording(twin, robot)
    bag = write_recording(recording, root / 'clean', robot.topics)
    fixtures = Fixtures(root, robot, recording, bag)
    if train:
        run = train_run([twin], robot, 'motor', ['rnea_lq'], root / 'run', progress=False)
        fixtures.run_dir = run.out
    return fixtures


def broken_bag(fx: Fixtures, name: str, **changes: object) -> Path:
    """The clean recording with some arrays changed, written as a contract bag."""
    from id_learning.dataset.recording import write_recording

    return write_recording(replace(fx.recording, **changes), fx.path(name), fx.robot.topics)


def with_value(array: np.ndarray, sample: int, joint: int, value: float) -> np.ndarray:
    out = np.array(array, dtype=float, copy=True)
    out[sample, joint] = value
    return out


# -- cases: bags through train --------------------------------------------------------------------
def bag_cases(fx: Fixtures) -> Iterator[Case]:
    rec = fx.recording

    def train_on(bag: Path, *extra: str) -> list[str]:
        out = fx.path(f'run_{bag.name}')
        return ['train', '--bag', str(bag), '--models', 'rnea_lq', '--out', str(out), '--quiet',
                '--force', *extra]  # fmt: skip

    values = {
        'nan-position': ('position', np.nan, ('sample 40', 'joint_2', 'not finite')),
        'inf-velocity': ('velocity', np.inf, ('sample 40', 'joint_2', 'not finite')),
        'nan-current': ('current', np.nan, ('sample 40', 'joint_2', 'not finite')),
        '1e300-position': ('position', 1e300, ('sample 40', 'joint_2', 'outside the limits')),
        '6x-velocity': ('velocity', 6 * 1.40, ('sample 40', 'joint_2', 'exceeds')),
        'neg-1e300-current': ('current', -1e300, ()),
    }
    for name, (field, value, words) in values.items():

        def run(field: str = field, value: float = value, words: tuple = words,
                name: str = name) -> Outcome:  # fmt: skip
            bag = broken_bag(fx, name, **{field: with_value(getattr(rec, field), 40, 1, value)})
            return cli(train_on(bag), expect=words or ('current',))

        yield Case(f'bag {name}', 'train', run)

    def degrees() -> Outcome:
        bag = broken_bag(fx, 'degrees', position=np.degrees(rec.position))
        return cli(train_on(bag), expect=('degrees',))

    yield Case('bag positions in degrees', 'train', degrees)

    def stamps(kind: str) -> Outcome:
        stamps_ns = rec.stamps_ns.copy()
        if kind == 'repeat':
            stamps_ns[50] = stamps_ns[49]
        elif kind == 'backwards':
            stamps_ns[50] = stamps_ns[48]
        else:
            stamps_ns[50:] += 10 * 8_000_000
        bag = broken_bag(fx, f'stamps_{kind}', stamps_ns=stamps_ns)
        # A stamp moved back also moves its message back in log-time order: the loader names
        # the first stamp that does not advance, wherever that lands.
        words = {'repeat': ('repeats', 'sample 50'), 'backwards': ('time stamp', 'sample'),
                 'gap': ('gap', 'sample 50')}[kind]  # fmt: skip
        return cli(train_on(bag), expect=words)

    for kind in ('repeat', 'backwards', 'gap'):
        yield Case(f'bag stamp {kind}', 'train', lambda kind=kind: stamps(kind))

    def renamed() -> Outcome:
        joints = (*rec.joints[:5], 'wrist_roll')
        bag = broken_bag(fx, 'renamed', joints=joints)
        return cli(train_on(bag), expect=('wrist_roll',))

    yield Case('bag joint renamed', 'train', renamed)

    def reordered() -> Outcome:
        order = [5, 4, 3, 2, 1, 0]
        bag = broken_bag(
            fx, 'reordered', joints=tuple(rec.joints[i] for i in order),
            position=rec.position[:, order], velocity=rec.velocity[:, order],
            current=rec.current[:, order],
        )  # fmt: skip
        outcome = cli(train_on(bag), expect=())
        # Reordering by name is documented: accepted, and the run says what it trained on.
        return Outcome('handled', outcome.said) if outcome.kind == 'silently_accepted' else outcome

    yield Case('bag joints reordered', 'train', reordered)

    def missing_topic() -> Outcome:
        from id_learning.bag import JOINT_STATE, BagWriter, iter_raw

        target = fx.path('no_currents')
        with BagWriter(target) as writer:
            writer.add_topic(fx.robot.topics.joint_states, JOINT_STATE)
            for _, log_ns, data in iter_raw(fx.bag, [fx.robot.topics.joint_states]):
                writer.write(fx.robot.topics.joint_states, log_ns, data)
        return cli(train_on(target), expect=('/motor_currents',))

    yield Case('bag without /motor_currents', 'train', missing_topic)

    def torn(kind: str) -> Outcome:
        target = fx.path(f'torn_{kind}')
        shutil.copytree(fx.bag, target)
        (mcap,) = target.glob('*.mcap')
        if kind == 'no-metadata':
            (target / 'metadata.yaml').unlink()
            return cli(train_on(target), expect=('bag recover',))
        data = mcap.read_bytes()
        if kind == 'truncated':
            mcap.write_bytes(data[: len(data) // 2])
        elif kind == 'zero-tail':
            mcap.write_bytes(data[: len(data) // 2] + bytes(len(data) - len(data) // 2))
        else:
            mcap.write_bytes(b'not an mcap file')
        return cli(train_on(target), expect=(str(target.name),))

    for kind in ('no-metadata', 'truncated', 'zero-tail', 'garbage'):
        yield Case(f'bag {kind}', 'train', lambda kind=kind: torn(kind))

    def unpaired(flag: bool) -> Outcome:
        from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, iter_raw

        target = fx.path(f'unpaired_{flag}')
        topics = [fx.robot.topics.joint_states, fx.robot.topics.motor_currents]
        with BagWriter(target) as writer:
            for topic in topics:
                writer.add_topic(topic, JOINT_STATE)
            for topic, log_ns, data in iter_raw(fx.bag, topics):
                writer.write(topic, log_ns, data)
            stamp = int(rec.stamps_ns[-1]) + 8_000_000  # one more joint state, no current
            q, v = rec.position[-1], rec.velocity[-1]
            extra = encode_joint_state(stamp, rec.joints, q, v, np.zeros(0))
            writer.write(topics[0], stamp, extra)
        if flag:
            return cli(train_on(target, '--trim-unpaired-tail'), expect=(),
                       handled=('unpaired',))  # fmt: skip
        return cli(train_on(target), expect=('--trim-unpaired-tail',))

    yield Case('bag unpaired tail', 'train', lambda: unpaired(False))
    yield Case('bag unpaired tail, --trim-unpaired-tail', 'train', lambda: unpaired(True))

    def no_bag() -> Outcome:
        return cli(train_on(fx.path('absent')), expect=('absent',))

    yield Case('bag folder absent', 'train', no_bag)


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


# -- cases: replay plan and recovery --------------------------------------------------------------
def replay_and_recover_cases(fx: Fixtures) -> Iterator[Case]:
    rec = fx.recording

    def replay(name: str, **changes: object) -> Outcome:
        from id_learning.errors import BagError
        from id_learning.nodes.params import ReplayConfig
        from id_learning.nodes.replay import build_plan

        bag = broken_bag(fx, f'replay_{name}', **changes)
        return raises(lambda: build_plan(ReplayConfig(bag=str(bag)), fx.robot), BagError,
                      ('sample 60',))  # fmt: skip

    cases = {
        'nan position': {'position': with_value(rec.position, 60, 0, np.nan)},
        '1e300 position': {'position': with_value(rec.position, 60, 0, 1e300)},
        '6x velocity': {'velocity': with_value(rec.velocity, 60, 0, 6 * 1.7)},
    }
    try:
        import rclpy  # noqa: F401 -- the replay's plan imports the node module
    except ImportError:
        cases = {}
    for name, changes in cases.items():
        yield Case(
            f'replay {name}', 'replay', lambda n=name, c=changes: replay(n.replace(' ', '_'), **c)
        )

    def recover(fraction: float, chunk_bytes: int | None) -> Outcome:
        from id_learning.bag import BagWriter, bag_info, iter_raw
        from id_learning.bag.recover import recover_bag

        name = f'cut_{fraction}_{chunk_bytes}'
        source = fx.path(f'{name}_source')
        if chunk_bytes is None:
            shutil.copytree(fx.bag.parent / 'twin', source)
        else:
            with BagWriter(source, chunk_bytes=chunk_bytes) as writer:
                for topic in (fx.robot.topics.joint_states, fx.robot.topics.motor_currents):
                    writer.add_topic(topic, 'sensor_msgs/msg/JointState')
                for topic, log_ns, data in iter_raw(
                    fx.bag, list(fx.robot.topics.__dict__.values())
                ):
                    writer.write(topic, log_ns, data)
        total = sum(t.count for t in bag_info(source).topics)
        target = fx.path(name)
        shutil.copytree(source, target)
        (target / 'metadata.yaml').unlink()
        for mcap in target.glob('*.mcap'):
            data = mcap.read_bytes()
            mcap.write_bytes(data[: int(len(data) * fraction)])
        try:
            recover_bag(target)
        except Exception as error:
            return Outcome('traceback', f'{type(error).__name__}: {error}')
        kept = sum(t.count for t in bag_info(target).topics)
        share = kept / total
        kind = 'handled' if share >= 0.8 * fraction else 'data_lost'
        return Outcome(
            kind, f'kept {kept} of {total} messages ({share:.0%}) cut at {fraction:.0%}'
        )

    for fraction in (0.5, 0.25, 0.9):
        yield Case(f'recover simulate bag cut at {fraction:.0%}', 'bag recover',
                   lambda f=fraction: recover(f, None))  # fmt: skip
    for chunk in (4096, 1 << 20):
        yield Case(f'recover bag of {chunk} B chunks cut at 50%', 'bag recover',
                   lambda c=chunk: recover(0.5, c))  # fmt: skip


# -- cases: import --------------------------------------------------------------------------------
def import_cases(fx: Fixtures) -> Iterator[Case]:
    rec = fx.recording
    joints = rec.joints
    mapping = {
        'time': {'column': 't', 'unit': 's'},
        'joints': [
            {'name': name, 'position': {'column': f'q{j}', 'unit': 'rad'},
             'velocity': {'column': f'v{j}', 'unit': 'rad/s'},
             'current': {'column': f'i{j}', 'unit': 'A'}}
            for j, name in enumerate(joints)
        ],
    }  # fmt: skip

    def write_log(name: str, change: Callable[[np.ndarray], np.ndarray] | None = None,
                  text: str | None = None, mapping_change: Callable[[dict], None] | None = None,
                  ) -> tuple[Path, Path]:  # fmt: skip
        import yaml

        n = 300
        t = (rec.stamps_ns[:n] - rec.stamps_ns[0]) * 1e-9
        table = np.column_stack([t, rec.position[:n], rec.velocity[:n], rec.current[:n]])
        if change is not None:
            table = change(table)
        header = ['t', *(f'q{j}' for j in range(6)), *(f'v{j}' for j in range(6)),
                  *(f'i{j}' for j in range(6))]  # fmt: skip
        log = fx.path(f'{name}.csv')
        body = '\n'.join(','.join(repr(float(x)) for x in row) for row in table)
        log.write_text(text if text is not None else ','.join(header) + '\n' + body + '\n')
        this = json.loads(json.dumps(mapping))
        if mapping_change is not None:
            mapping_change(this)
        mapping_file = fx.path(f'{name}.yaml')
        mapping_file.write_text(yaml.safe_dump(this))
        return log, mapping_file

    def run_import(name: str, words: tuple[str, ...], **kwargs: object) -> Outcome:
        log, mapping_file = write_log(name, **kwargs)  # type: ignore[arg-type]
        out = fx.path(f'{name}_bag')
        outcome = cli(['import', str(log), '--mapping', str(mapping_file), '--out', str(out)],
                      expect=words)  # fmt: skip
        if outcome.kind == 'clear_error' and out.exists():
            return Outcome('silently_accepted', f'refused but wrote {out}')
        return outcome

    def cell(row: int, col: int, value: float) -> Callable[[np.ndarray], np.ndarray]:
        def change(table: np.ndarray) -> np.ndarray:
            table = table.copy()
            table[row, col] = value
            return table

        return change

    def degrees(table: np.ndarray) -> np.ndarray:
        table = table.copy()
        table[:, 1:7] = np.degrees(table[:, 1:7])
        return table

    def backwards(table: np.ndarray) -> np.ndarray:
        table = table.copy()
        table[100, 0] = table[98, 0]
        return table

    def unit(m: dict) -> None:
        m['joints'][0]['position']['unit'] = 'furlong'

    def missing_column(m: dict) -> None:
        m['joints'][2]['velocity']['column'] = 'v_missing'

    def wrong_joint(m: dict) -> None:
        m['joints'][4]['name'] = 'elbow'

    table = {
        'import nan cell': ('nan_cell', ('line', 'q2'), {'change': cell(50, 3, np.nan)}),
        'import positions in degrees': ('degrees', ('degrees',), {'change': degrees}),
        'import 1e306 position': ('huge', ('1e+306',), {'change': cell(10, 1, 1e306)}),
        'import time backwards': ('backwards', ('backwards',), {'change': backwards}),
        'import unknown unit': ('unit', ('furlong',), {'mapping_change': unit}),
        'import missing column': ('column', ('v_missing',), {'mapping_change': missing_column}),
        'import joint not the robot': ('joint', ('elbow',), {'mapping_change': wrong_joint}),
        'import empty file': ('empty', ('empty',), {'text': ''}),
        'import text in a cell': ('text', ('abc',), {'text': 't,q0\n0.0,abc\n'}),
    }
    for name, (tag, words, kwargs) in table.items():
        yield Case(name, 'import', lambda t=tag, w=words, k=kwargs: run_import(t, w, **k))


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


# -- running --------------------------------------------------------------------------------------
def all_cases(fx: Fixtures) -> list[Case]:
    cases: list[Case] = []
    makers = (bag_cases, cli_cases, artifact_cases, predictor_cases, replay_and_recover_cases,
              import_cases, config_cases, other_door_cases)  # fmt: skip
    for make in makers:
        cases += list(make(fx))
    return cases


def run_cases(cases: list[Case]) -> list[tuple[Case, Outcome]]:
    results = []
    for case in cases:
        try:
            outcome = case.run()
        except Exception as error:
            outcome = Outcome('traceback', f'{type(error).__name__}: {error}')
        results.append((case, outcome))
        print(f'{outcome.kind:<18} {case.door:<12} {case.name}', file=sys.stderr, flush=True)
    return results


def summary(results: list[tuple[Case, Outcome]]) -> dict[str, object]:
    counts = Counter(outcome.kind for _, outcome in results)
    return {
        'cases': len(results),
        **{kind: counts.get(kind, 0) for kind in KINDS},
        'not_clear': [
            {'case': case.name, 'door': case.door, 'outcome': outcome.kind, 'said': outcome.said}
            for case, outcome in results
            if outcome.kind not in ('clear_error', 'handled')
        ],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, help='keep the broken files here')
    parser.add_argument('--only', default='', help='run the cases whose name holds this')
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        root = args.out or Path(scratch)
        root.mkdir(parents=True, exist_ok=True)
        print('building the fixtures (twin recording, rnea_lq run) ...', file=sys.stderr)
        fx = build_fixtures(root, train=True)
        cases = [c for c in all_cases(fx) if args.only in c.name]
        results = run_cases(cases)
    document = summary(results)
    print(json.dumps(document))
    return 0


if __name__ == '__main__':
    sys.exit(main())
