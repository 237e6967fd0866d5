"""Repeated list items, empty names and contradictory options are refused before any work."""

from __future__ import annotations

import argparse

import pytest

from id_learning.cli import options
from id_learning.cli.main import main
from id_learning.errors import ConfigError


def test_model_kinds_repeat() -> None:
    with pytest.raises(ConfigError, match="--models 'rnea_lq,rnea_lq': rnea_lq given twice"):
        options.model_kinds('rnea_lq,rnea_lq')
    assert options.model_kinds('study,rnea_id')[-1] == 'rnea_id'


def test_effect_names_repeat() -> None:
    with pytest.raises(ConfigError, match=r'--effects .*cogging given twice'):
        options.effect_names('cogging, cogging')
    assert options.comma_names('a,a') == ['a', 'a']  # no option: no check


def test_refuse_contradictions_forms() -> None:
    args = argparse.Namespace(split='contiguous', split_seed=0, force=True, plot=None)
    with pytest.raises(ConfigError, match='--split-seed means nothing with --split contiguous'):
        options.refuse_contradictions(args, [options.SPLIT_SEED_CONTRADICTION])
    with pytest.raises(ConfigError, match='--force means nothing without --plot'):
        options.refuse_contradictions(args, [('--force', '!--plot', 'nothing to replace')])
    options.refuse_contradictions(
        argparse.Namespace(split='shuffled', split_seed=3), [options.SPLIT_SEED_CONTRADICTION]
    )
    assert options.split_seed(argparse.Namespace(split_seed=None)) == 0


@pytest.mark.parametrize(
    ('argv', 'words'),
    [
        (['train', '--models', 'rnea_lq,rnea_lq'], ('--models', 'rnea_lq given twice')),
        (['train', '--split', 'contiguous', '--split-seed', '7'], ('--split-seed', 'contiguous')),
        (['train', '--split-seed', '0'], ('--split-seed', 'contiguous')),
        (['demo', '--skip-training', '--train-seconds', '5'], ('--train-seconds', 'skip')),
        (['demo', '--skip-training', '--online-seconds', '1'], ('--online-seconds', 'skip')),
        (['diagnose', '--effects', 'cogging,cogging'], ('--effects', 'cogging given twice')),
        (['train', '--models', 'mlp', '--hyper', 'mlp.device=cuda', '--device', 'cpu'],
         ('--hyper mlp.device=cuda contradicts --device cpu',)),
    ],
)  # fmt: skip
def test_cli_refuses(argv: list[str], words: tuple[str, ...], tmp_path, capsys) -> None:
    bag = ['--bag', str(tmp_path / 'no_bag')]  # refused before the bag is read
    assert main(argv + ([] if argv[0] == 'demo' else bag) + ['--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err
    assert all(word in err for word in words), err
    assert not (tmp_path / 'o').exists()


def test_sweep_empty_study_name(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(['sweep', '--bag', 'x', '--model', 'mlp', '--study-name', '', '--out', str(tmp_path)])
    assert '--study-name: must not be empty' in capsys.readouterr().err


def test_inspect_force_without_a_plot_is_refused(capsys):
    assert main(['inspect', 'bags/default', '--force']) == 2
    assert '--force' in capsys.readouterr().err


def test_a_hyper_file_device_contradicting_device_is_refused_unless_an_item_replaces_it(
    tmp_path, capsys
) -> None:
    path = tmp_path / 'best.yaml'
    path.write_text('mlp:\n  device: cuda\n')
    argv = ['train', '--models', 'mlp', '--hyper-file', str(path), '--device', 'cpu',
            '--bag', str(tmp_path / 'no_bag'), '--out', str(tmp_path / 'o')]  # fmt: skip
    assert main(argv) == 2
    assert f'--hyper-file {path} (mlp.device: cuda) contradicts --device cpu' in (
        capsys.readouterr().err
    )
    assert main([*argv, '--hyper', 'mlp.device=cpu']) == 2  # the bag, now
    assert 'contradicts' not in capsys.readouterr().err
    options.refuse_two_devices({'mlp': {'device': 'cuda'}}, 'auto', '')  # its own choice
