"""Every command-line flag a message suggests exists, and --trim-unpaired-tail does its job."""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

import pytest
from support import twin_config

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.cli.main import build_parser
from id_learning.cli.main import main as cli
from id_learning.twin import simulate

PACKAGE = Path(__file__).resolve().parents[1] / 'id_learning'
FLAG = re.compile(r'(?<![\w-])--[a-z][a-z0-9-]+')
#: Flags of programs other than ours that messages may name (ROS 2's own arguments, which the
#: nodes read where they look for their parameters).
FOREIGN = {'--ros-args', '--params-file', '--param', '--remap', '--enclave', '--log-level',
           '--log-config-file', '--log-file-name'}  # fmt: skip


def _options(parser: argparse.ArgumentParser) -> set[str]:
    found = set()
    for action in parser._actions:
        found.update(option for option in action.option_strings if option.startswith('--'))
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _options(sub)
    return found


def _suggested_flags() -> dict[str, set[str]]:
    """Flags named in string literals of the package, with the files naming them."""
    where: dict[str, set[str]] = {}
    for path in PACKAGE.rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                for flag in FLAG.findall(node.value):
                    where.setdefault(flag, set()).add(path.name)
    return where


def test_every_flag_a_message_or_help_names_is_an_option_of_the_tool():
    known = _options(build_parser()) | FOREIGN
    suggested = _suggested_flags()
    assert '--trim-unpaired-tail' in suggested  # the scan sees the messages
    missing = {flag: sorted(files) for flag, files in suggested.items() if flag not in known}
    assert not missing, f'flags named in messages but not accepted by any command: {missing}'


@pytest.fixture(scope='module')
def torn_bag(tmp_path_factory):
    """A 40 s twin recording whose last two current messages were never written."""
    recording = simulate(twin_config(40.0, seed=4)).recording
    path = tmp_path_factory.mktemp('torn') / 'bag'
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            q, v = recording.position[k], recording.velocity[k]
            writer.write(
                '/joint_states', stamp, encode_joint_state(stamp, recording.joints, q, v, [])
            )
            if k < recording.n_samples - 2:
                current = encode_joint_state(stamp, recording.joints, [], [], recording.current[k])
                writer.write('/motor_currents', stamp, current)
    return path, recording.n_samples


def test_train_refuses_a_torn_bag_naming_the_flag_and_trims_it_on_request(
    torn_bag, tmp_path, capsys, caplog
):
    path, _ = torn_bag
    out = tmp_path / 'run'
    args = ['train', '--bag', str(path), '--models', 'rnea_lq', '--out', str(out), '--quiet']
    assert cli(args) == 2
    error = capsys.readouterr().err
    assert 'have no partner' in error
    assert '--trim-unpaired-tail' in error
    assert not out.exists()
    assert cli([*args, '--trim-unpaired-tail']) == 0
    assert 'dropped the last 2 unpaired message(s) of /joint_states' in caplog.text
    assert (out / 'models' / 'rnea_lq' / 'model.json').is_file()
