"""The command line's help says what the commands do: every command listed, counts that hold."""

from __future__ import annotations

import argparse

from id_learning.cli.demo import DEMO_MODELS
from id_learning.cli.main import build_parser
from id_learning.cli.options import model_kinds
from id_learning.models.registry import MODEL_KINDS, STUDY_MODELS

NUMBERS = {7: 'seven', 9: 'nine', 11: 'eleven'}


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (action,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_the_top_level_help_names_every_subcommand_in_its_summary_and_its_list():
    parser = build_parser()
    commands = subcommands(parser)
    assert {'demo', 'train', 'closed-loop', 'sweep'} <= set(commands)
    help_text = parser.format_help()
    summary = ' '.join(help_text.split('Commands:', 1)[1].split(';', 1)[0].split())
    named = [name.strip() for name in summary.split(',')]
    assert named == list(commands), f'the summary names {named}, the parser has {list(commands)}'
    listing = help_text.split('positional arguments:', 1)[1]
    for name in commands:
        assert f'\n    {name} ' in listing, name


def test_the_demo_help_counts_the_kinds_it_trains_by_default():
    demo = subcommands(build_parser())['demo']
    n_kinds = len(model_kinds(DEMO_MODELS))
    assert n_kinds == 9
    parent = build_parser().format_help()
    assert f'{NUMBERS[n_kinds]} model kinds' in ' '.join(parent.split())
    assert 'seven' not in ' '.join(parent.split())
    assert DEMO_MODELS in ' '.join(demo.format_help().split())


def test_the_registry_holds_the_studys_seven_and_six_on_identified_physics():
    assert len(STUDY_MODELS) == 7
    assert set(MODEL_KINDS) - set(STUDY_MODELS) == {
        'rnea_id', 'rnea_id_mlp', 'rnea_effects', 'rnea_effects_mlp', 'delan_id', 'lnn_mlp_id'
    }  # fmt: skip
