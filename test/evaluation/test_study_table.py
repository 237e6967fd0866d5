"""The study table (``train --study-table``) is a user-given JSON: every value is checked.

A value of the wrong type or range is refused with a ConfigError naming the file, the key path
and the value, never another exception and never read as something else (a string read digit by
digit, ``true`` as 1, a negative RMSE put into the report as it is).
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.evaluation.study import load_study_table
from id_learning.models.registry import MODEL_KINDS

AXES = [f'axis_{k}' for k in range(1, 7)]
ROW = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]


def valid_table() -> dict[str, Any]:
    return {
        'joints': list(AXES),
        'rmse_normalised': {'mlp': list(ROW), 'rnea_mlp': list(ROW)},
        'source': 'placeholder',
        'metric': 'test RMSE',
        'split_note': '70/30',
        'findings': ['one', 'two'],
    }


def write(path: Path, content: Any) -> Path:
    path.write_text(json.dumps(content))
    return path


def refusal(path: Path) -> str:
    with pytest.raises(ConfigError) as err:
        load_study_table(path, n_joints=6)
    return str(err.value)


def test_a_valid_table_is_read_as_written(tmp_path: Path) -> None:
    table = load_study_table(write(tmp_path / 't.json', valid_table()), n_joints=6)
    assert table.joints == tuple(AXES)
    assert table.rmse_normalised == {'mlp': tuple(ROW), 'rnea_mlp': tuple(ROW)}
    assert (table.source, table.metric, table.split_note) == ('placeholder', 'test RMSE', '70/30')
    assert table.findings == ('one', 'two')


def test_optional_keys_may_be_absent_and_notes_are_not_read(tmp_path: Path) -> None:
    content = {'joints': AXES, 'rmse_normalised': {'lstm': [0, 0, 0, 0, 0, 1]}, 'robot': 3}
    table = load_study_table(write(tmp_path / 't.json', content))
    assert table.rmse_normalised == {'lstm': (0.0, 0.0, 0.0, 0.0, 0.0, 1.0)}
    assert (table.source, table.metric, table.split_note, table.findings) == ('', '', '', ())


def _with(path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    content = valid_table()
    node: Any = content
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return content


@pytest.mark.parametrize(
    ('path', 'value', 'message'),
    [
        # The probe's cases: ST_list/G09, ST_int, ST_str, ST_neg, ST_bool.
        (('rmse_normalised',), [1, 2], r'rmse_normalised: must be a non-empty object .* \[1, 2\]'),
        (('joints',), 6, r'joints: must be a non-empty list of axis names, got a number 6'),
        (('rmse_normalised', 'mlp'), '123456', r'rmse_normalised\.mlp: needs 6 .*"123456"'),
        (('rmse_normalised', 'mlp', 0), -0.1, r'rmse_normalised\.mlp\[0\]: .*>= 0, got -0\.1'),
        (('rmse_normalised', 'mlp', 5), True, r'rmse_normalised\.mlp\[5\]: .*, got true'),
        # Around them.
        (('rmse_normalised', 'mlp', 2), '0.3', r'mlp\[2\]: .*not a string.*without quotes: 0\.3'),
        (('rmse_normalised', 'mlp', 1), None, r'rmse_normalised\.mlp\[1\]: .*, got null'),
        (('rmse_normalised', 'mlp', 1), [0.1], r'rmse_normalised\.mlp\[1\]: .*, got \[0\.1\]'),
        (('rmse_normalised', 'mlp', 1), 10**400, r'rmse_normalised\.mlp\[1\]: must be a finite'),
        (('rmse_normalised', 'mlp'), {'a': 1}, r'rmse_normalised\.mlp: needs 6 .*an object'),
        (('rmse_normalised', 'mlp'), ROW[:5], r'rmse_normalised\.mlp: needs 6 finite values'),
        (('rmse_normalised',), {}, r'rmse_normalised: must be a non-empty object'),
        (('rmse_normalised',), 'x', r'rmse_normalised: must be .*, got a string "x"'),
        (('rmse_normalised', ' '), ROW, r"rmse_normalised: a model kind must be a name, got ' '"),
        (('joints',), 'abcdef', r'joints: must be a non-empty list .*a string "abcdef"'),
        (('joints',), [], r'joints: must be a non-empty list'),
        (('joints', 3), 4, r'joints\[3\]: must be a non-empty name \(a string\), got a number 4'),
        (('joints', 3), '', r'joints\[3\]: must be a non-empty name'),
        (('joints', 3), 'axis_1', r"joints: \['axis_1'\] given more than once"),
        (('source',), 1, r'source: must be a string, got a number 1'),
        (('metric',), None, r'metric: must be a string, got null'),
        (('split_note',), ['a'], r'split_note: must be a string, got a list'),
        (('findings',), 'x', r'findings: must be a list of sentences \(strings\), got a string'),
        (('findings', 1), False, r'findings\[1\]: must be a string, got a boolean false'),
    ],
)
def test_a_wrong_value_is_refused_naming_file_key_and_value(
    tmp_path: Path, path: tuple[Any, ...], value: Any, message: str
) -> None:
    file = write(tmp_path / 'bad.json', _with(path, value))
    text = refusal(file)
    assert text.startswith(f'{file}: ')
    assert re.search(message, text), text


def test_non_finite_numbers_written_as_json_extensions_are_refused(tmp_path: Path) -> None:
    for word in ('NaN', 'Infinity', '-Infinity', '1e400'):
        file = tmp_path / 'bad.json'
        file.write_text(
            '{"joints": ["a", "b", "c", "d", "e", "f"], '
            f'"rmse_normalised": {{"mlp": [0.1, 0.1, {word}, 0.1, 0.1, 0.1]}}}}'
        )
        assert 'rmse_normalised.mlp[2]: must be a finite number >= 0' in refusal(file)


def test_a_kind_that_is_no_plain_word_is_quoted_in_the_key_path(tmp_path: Path) -> None:
    file = write(tmp_path / 'bad.json', _with(('rmse_normalised', 'a b\n'), 'x'))
    assert "rmse_normalised.'a b\\n': 'a b\\n' is no model kind" in refusal(file)


def test_json_nested_too_deeply_is_refused(tmp_path: Path) -> None:
    file = tmp_path / 'deep.json'
    file.write_text('[' * 200_000 + ']' * 200_000)
    assert 'cannot read study table' in refusal(file)


def test_a_huge_value_is_not_copied_whole_into_the_message(tmp_path: Path) -> None:
    file = write(tmp_path / 'bad.json', _with(('rmse_normalised', 'mlp'), 'x' * 100_000))
    assert len(refusal(file)) < 400


#: Any JSON value.
json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=7) | st.dictionaries(st.text(max_size=5), inner),
    max_leaves=12,
)

#: Where a value can be put: each field, a row, an element of a row, of joints, of findings.
fields = st.sampled_from(
    [
        ('joints',),
        ('joints', 0),
        ('rmse_normalised',),
        ('rmse_normalised', 'mlp'),
        ('rmse_normalised', 'new_kind'),
        ('rmse_normalised', 'mlp', 3),
        ('source',),
        ('metric',),
        ('split_note',),
        ('findings',),
        ('findings', 0),
    ]
)


def _acceptable(path: tuple[Any, ...], value: Any) -> bool:
    """Whether ``value`` at ``path`` makes a table the format allows (the oracle)."""

    def rmse(x: Any) -> bool:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            return False
        finite = abs(x) <= sys.float_info.max if isinstance(x, int) else math.isfinite(x)
        return finite and x >= 0

    def row(x: Any) -> bool:
        return isinstance(x, list) and len(x) == 6 and all(rmse(v) for v in x)

    match path:
        case ('joints',):
            return (
                isinstance(value, list)
                and len(value) == 6
                and all(isinstance(j, str) and j.strip() for j in value)
                and len(set(value)) == 6
            )
        case ('joints', _):
            return isinstance(value, str) and bool(value.strip()) and value not in AXES[1:]
        case ('rmse_normalised',):
            return (
                isinstance(value, dict)
                and bool(value)
                and all(k in MODEL_KINDS and row(v) for k, v in value.items())
            )
        case ('rmse_normalised', kind):
            return kind in MODEL_KINDS and row(value)
        case ('rmse_normalised', _, _):
            return rmse(value)
        case ('findings',):
            return isinstance(value, list) and all(isinstance(f, str) for f in value)
        case _:
            return isinstance(value, str)


@settings(max_examples=300, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=fields, value=json_values)
def test_any_json_value_in_any_field_is_read_or_refused_clearly(
    tmp_path: Path, path: tuple[Any, ...], value: Any
) -> None:
    file = write(tmp_path / 'any.json', _with(path, value))
    if _acceptable(path, value):
        table = load_study_table(file, n_joints=6)
        assert all(len(r) == 6 for r in table.rmse_normalised.values())
        assert all(x >= 0 and math.isfinite(x) for r in table.rmse_normalised.values() for x in r)
    else:
        text = refusal(file)  # a ConfigError, no other exception
        assert text.startswith(f'{file}: ')
        assert path[0] in text
