"""Fault cases of recordings: bags through train, the replay's plan, recovery, imported logs."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from fault_kit import (
    Case,
    Fixtures,
    Outcome,
    broken_bag,
    cli,
    raises,
    with_value,
)


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
