"""Every hyper-parameter is checked by type and range where a config is made, naming kind.key."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any, get_type_hints

import pytest

from id_learning.cli import options
from id_learning.errors import ConfigError
from id_learning.models.hyper_schema import HYPER_RANGES, _allowed
from id_learning.models.registry import MODEL_KINDS, make_config


@pytest.mark.parametrize('kind', sorted(MODEL_KINDS))
def test_every_number_field_of_every_kind_has_a_range_and_its_default_is_inside(kind: str) -> None:
    config_class = MODEL_KINDS[kind][0]
    hints = get_type_hints(config_class)
    default = make_config(kind)
    for item in fields(config_class):
        allowed = _allowed(hints[item.name])
        assert object not in allowed, f'{kind}.{item.name}: annotation not understood'
        if int in allowed or float in allowed:
            low, high = HYPER_RANGES[item.name]
            value = getattr(default, item.name)
            assert value is None or low <= value <= high, f'{kind}.{item.name}'


@pytest.mark.parametrize(
    ('kind', 'key', 'value', 'words'),
    [
        ('mlp', 'batch_size', 'abc', ('mlp.batch_size', "'abc'", 'an integer')),
        ('mlp', 'width', 'wide', ('mlp.width', "'wide'", 'an integer')),
        ('mlp', 'width', 32.7, ('mlp.width', '32.7', 'an integer')),
        ('mlp', 'width', True, ('mlp.width', 'True', 'an integer')),
        ('mlp', 'width', 10**9, ('mlp.width', '1000000000', '[1, 4096]')),
        ('lstm', 'hidden_size', 5000, ('lstm.hidden_size', '5000', '4096')),
        ('delan', 'depth', 17, ('delan.depth', '17', '[1, 16]')),
        ('lnn_mlp', 'dissipation_width', 0, ('lnn_mlp.dissipation_width', '[1, 4096]')),
        ('mlp', 'max_epochs', 10**7, ('mlp.max_epochs', '1e+06')),
        ('mlp', 'batch_size', 2**20 + 1, ('mlp.batch_size', '1.04858e+06')),
        ('mlp', 'learning_rate', float('nan'), ('mlp.learning_rate', 'finite number')),
        ('mlp', 'learning_rate', 'fast', ('mlp.learning_rate', 'finite number')),
        ('mlp', 'max_seconds', 'soon', ('mlp.max_seconds', 'finite number or null')),
        ('mlp', 'activation', 3, ('mlp.activation', 'a string')),
        ('rnea_id', 'delay', 1, ('rnea_id.delay', 'true or false')),
        ('rnea_id', 'iterations', 1000, ('rnea_id.iterations', '[1, 100]')),
        ('mlp', 'seed', -1, ('mlp.seed', '[0, 4.29497e+09]')),
    ],
)
def test_a_bad_value_is_refused_in_one_line_naming_kind_key_value_and_what_is_allowed(
    kind: str, key: str, value: Any, words: tuple[str, ...]
) -> None:
    with pytest.raises(ConfigError) as refused:
        make_config(kind, **{key: value})
    text = str(refused.value)
    assert '\n' not in text
    for word in words:
        assert word in text


def test_choices_are_named_by_the_configs_own_check() -> None:
    with pytest.raises(ConfigError, match=r"mlp: activation must be one of .*'swish'"):
        make_config('mlp', activation='swish')


def test_ints_where_floats_are_declared_become_floats_and_good_values_pass() -> None:
    config = make_config('mlp', learning_rate=1, width=4096, depth=16, batch_size=2**20)
    assert isinstance(config.learning_rate, float)
    assert config.learning_rate == 1.0
    assert config.width == 4096  # type: ignore[attr-defined]


def test_an_unknown_key_is_still_named_with_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"mlp: unknown hyper-parameter\(s\) \['widht'\]"):
        make_config('mlp', widht=3)


def test_a_hyper_item_given_twice_is_refused_naming_both_values() -> None:
    with pytest.raises(ConfigError, match=r'--hyper mlp.width given twice \(64 and 8\)'):
        options.hyper_parameters(['mlp.width=64', 'mlp.width=8'])
    assert options.hyper_parameters(['mlp.width=64', 'lstm.width=8']) == {
        'mlp': {'width': 64},
        'lstm': {'width': 8},
    }


def test_a_hyper_file_value_of_the_wrong_type_is_refused_where_training_resolves_it(
    tmp_path: Path,
) -> None:
    from id_learning.training.fitting import resolve_overrides

    path = tmp_path / 'best.yaml'
    path.write_text('mlp:\n  width: wide\n', encoding='utf-8')
    hyper = options.hyper_file(str(path))
    with pytest.raises(ConfigError, match=r"mlp.width: must be an integer, got 'wide'"):
        resolve_overrides(['mlp'], hyper, max_seconds=None, device='cpu')
