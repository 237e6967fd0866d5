"""Fault cases of bag folders: metadata.yaml that lies about its storage, a damaged ground truth,
an edited copy of one recording, a misshapen twin effects section; through the CLI and the
replay's plan. Each broken bag is a copy of the fixtures' clean bag, edited in a temp folder.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import yaml
from fault_kit import REPO, ROBOT_FILE, Case, Fixtures, Outcome, cli, raises

__all__ = ['bag_more_cases']


def _copy(fx: Fixtures, name: str, edit: Callable[[dict[str, Any]], None] | None = None) -> Path:
    """A copy of the clean bag as ``name``, its metadata info mapping passed through ``edit``."""
    out = fx.path(f'more_{name}')
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(fx.bag, out)
    if edit is not None:
        meta = out / 'metadata.yaml'
        data = yaml.safe_load(meta.read_text(encoding='utf-8'))
        edit(data['rosbag2_bagfile_information'])
        meta.write_text(yaml.safe_dump(data), encoding='utf-8')
    return out


def _compressed(info: dict[str, Any]) -> None:
    info.update(compression_format='zstd', compression_mode='FILE')


def _retyped(info: dict[str, Any]) -> None:
    for entry in info['topics_with_message_count']:
        if entry['topic_metadata']['name'] == '/motor_currents':
            entry['topic_metadata']['type'] = 'std_msgs/msg/Float64MultiArray'


def _noted(info: dict[str, Any]) -> None:
    info['custom_data'] = {'note': 'copied and edited'}


def _plan(bag: Path, fx: Fixtures) -> object:
    from id_learning.nodes.params import ReplayConfig
    from id_learning.nodes.replay import build_plan

    return build_plan(ReplayConfig(bag=str(bag)), fx.robot)  # type: ignore[arg-type]


def _without(fx: Fixtures, name: str, drop: Callable[[int, str], bool]) -> Path:
    """The clean bag rewritten without the messages ``drop(index, topic)`` selects."""
    from id_learning.bag import BagWriter, bag_info, iter_raw

    info = bag_info(fx.bag)
    out = fx.path(f'more_{name}')
    shutil.rmtree(out, ignore_errors=True)
    names = [t.name for t in info.topics]
    messages = list(iter_raw(fx.bag, names))
    with BagWriter(out) as writer:
        for topic in info.topics:
            writer.add_topic(topic.name, topic.msgtype)
        for k, (topic, log_ns, data) in enumerate(messages):
            if not drop(len(messages) - 1 - k, topic):
                writer.write(topic, log_ns, data)
    return out


def bag_more_cases(fx: Fixtures) -> Iterator[Case]:
    """Bags whose metadata.yaml, ground truth or copies mislead, and a misshapen twin config."""
    from id_learning.errors import BagError

    def train_on(*bags: Path) -> list[str]:
        flags = [arg for bag in bags for arg in ('--bag', str(bag))]
        return ['train', *flags, '--models', 'rnea_lq', '--out', str(fx.path('more_run')),
                '--quiet', '--force']  # fmt: skip

    def claimed_compression(door: str) -> Outcome:
        bag = _copy(fx, f'compressed_{door}', _compressed)
        argv = ['inspect', str(bag)] if door == 'inspect' else train_on(bag)
        return cli(argv, expect=(bag.name, 'compression_format zstd', '.mcap'))

    yield Case('bag metadata claims zstd FILE compression (inspect)', 'inspect',
               lambda: claimed_compression('inspect'))  # fmt: skip
    yield Case('bag metadata claims zstd FILE compression (train)', 'train',
               lambda: claimed_compression('train'))  # fmt: skip

    def retyped_train() -> Outcome:
        bag = _copy(fx, 'retyped_train', _retyped)
        return cli(train_on(bag), expect=('/motor_currents', 'Float64MultiArray'))

    yield Case('bag metadata types a topic otherwise than its storage', 'train', retyped_train)

    def edited_copy() -> Outcome:
        return cli(train_on(fx.bag, _copy(fx, 'noted', _noted)), expect=('same data',))

    yield Case('bag given twice, the copy with an edited metadata.yaml', 'train', edited_copy)

    def garbage_ground_truth() -> Outcome:
        from id_learning.errors import DatasetError
        from id_learning.twin.ground_truth import read_ground_truth

        twin = fx.bag.parent / 'twin'
        bag = fx.path('more_gt_garbage')
        shutil.rmtree(bag, ignore_errors=True)
        shutil.copytree(twin, bag)
        (bag / 'ground_truth.json').write_text('{not json', encoding='utf-8')
        return raises(lambda: read_ground_truth(bag, 'motor'), DatasetError,
                      ('ground_truth.json',))  # fmt: skip

    yield Case('twin bag with a corrupt ground_truth.json', 'ground truth', garbage_ground_truth)

    def effects_list() -> Outcome:
        data = yaml.safe_load((REPO / 'config' / 'twin_default.yaml').read_text('utf-8'))
        data.update(effects=['viscous_friction'], robot=str(ROBOT_FILE))
        path = fx.path('more_effects_list.yaml')
        path.write_text(yaml.safe_dump(data), encoding='utf-8')
        argv = ['simulate', '--config', str(path), '--out', str(fx.path('more_sim')),
                '--duration', '2', '--quiet']  # fmt: skip
        return cli(argv, expect=(path.name, 'effects: expected a mapping'))

    yield Case('twin config effects as a list', 'simulate', effects_list)

    try:
        import rclpy  # noqa: F401 -- the replay's plan imports the node module
    except ImportError:
        return

    def retyped_replay() -> Outcome:
        bag = _copy(fx, 'retyped_replay', _retyped)
        return raises(lambda: _plan(bag, fx), BagError, ('/motor_currents', 'metadata.yaml'))

    yield Case('replay of a topic typed otherwise in metadata.yaml', 'replay', retyped_replay)

    def empty_source() -> Outcome:
        bag = _without(fx, 'js_empty', lambda _, topic: topic == '/joint_states')
        return raises(lambda: _plan(bag, fx), BagError, ('/joint_states', 'no message'))

    yield Case('replay of a bag whose /joint_states is empty', 'replay', empty_source)

    def unpaired() -> Outcome:
        bag = _without(fx, 'tail', lambda from_end, topic: from_end == 0)
        try:
            plan = _plan(bag, fx)
        except Exception as err:
            return Outcome('traceback', f'{type(err).__name__}: {err}')
        said = ' '.join(getattr(plan, 'warnings', ()))
        named = 'unpaired tail' in said and '/' in said
        return Outcome('handled' if named else 'silently_accepted', said[-400:] or 'no warning')

    yield Case('replay of a bag with an unpaired last message', 'replay', unpaired)
