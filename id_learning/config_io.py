"""Strict config helpers shared by every loader: YAML without duplicate keys, checked numbers.

Every YAML file the package reads (robot, twin, import mapping, hyper-parameter and node
parameter files) goes through ``load_yaml_mapping`` or ``parse_yaml``, which refuse a key given
twice in one mapping (YAML's last-one-wins would drop the first silently). Numbers from configs
go through ``finite_number`` or ``float_vector``: NaN and inf are refused with the key, the value
and the allowed range, since NaN slips through comparisons such as ``x < 0``.

Files are read whole through ``bounded_read.read_capped`` (re-exported here).
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from id_learning.bounded_read import (
    MAX_CONFIG_BYTES,
    PIPE_IDLE_S,
    PIPE_WRITER_S,
    not_a_file,
    pipe_waits_stop_when,
    read_capped,
    special_kind,
)
from id_learning.errors import ConfigError

__all__ = [
    'MAX_CONFIG_BYTES',
    'PIPE_IDLE_S',
    'PIPE_WRITER_S',
    'DuplicateKeyError',
    'broken_link',
    'check_keys',
    'config_base',
    'describe_range',
    'finite_number',
    'float_vector',
    'load_yaml_mapping',
    'loads_unique',
    'not_a_file',
    'number_hint',
    'parse_yaml',
    'pipe_waits_stop_when',
    'range_problem',
    'read_capped',
    'readonly',
    'short_json',
    'special_kind',
    'topic_name_problem',
]


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe loader that refuses a key given twice in one mapping, naming both lines."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        """The mapping of ``node``; a key seen before raises, naming both lines."""
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == 'tag:yaml.org,2002:merge':
                continue  # '<<' merges are YAML's own way of repeating keys on purpose
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                first = seen.get(key)
            except TypeError:
                continue  # an unhashable key: the base class refuses it
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None, None, f'duplicate key {key!r} at lines {first} and {line}', None
                )
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


# YAML 1.2 floats: PyYAML (YAML 1.1) reads 1e-3 and 5E+2 as strings, since 1.1 wants a dot.
_UniqueKeyLoader.yaml_implicit_resolvers = {
    key: list(resolvers) for key, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_UniqueKeyLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.VERBOSE,
    ),
    list('-+0123456789.'),
)


def config_base(path: Path, value: object) -> Path:
    """The folder a config file's relative path ``value`` is read from.

    The config's own folder; for a config reached through a symbolic link, its target's folder
    where ``value`` exists there and not beside the link (the author wrote it beside the file).
    """
    base = path.parent
    if not isinstance(value, str) or Path(value).is_absolute() or (base / value).exists():
        return base
    real = path.resolve().parent
    return real if (real / value).exists() else base


def parse_yaml(text: str, where: str) -> Any:
    """Parse YAML text safely, refusing a key given twice in one mapping.

    Args:
        text: the YAML document.
        where: the file (or option) named in errors.

    Raises:
        ConfigError: not valid YAML, or a duplicate key (names it and both lines).
    """
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass: safe
    except yaml.constructor.ConstructorError as err:
        if err.problem and err.problem.startswith('duplicate key'):
            raise ConfigError(f'{where}: {err.problem}; give each key once') from None
        raise ConfigError(f'{where}: not valid YAML: {err}') from err
    except yaml.YAMLError as err:
        raise ConfigError(f'{where}: not valid YAML: {err}') from err
    except RecursionError:
        raise ConfigError(f'{where}: YAML nested too deeply to read') from None


def load_yaml_mapping(path: Path) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping; a key given twice is refused.

    Raises:
        ConfigError: the file is missing, a device, over ``MAX_CONFIG_BYTES``, not UTF-8, not
            valid YAML, repeats a key (names the key and both lines), or is not a mapping.
    """
    data = read_capped(path)
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ConfigError(f'{path}: cannot read config file: {err}') from err
    mapping = parse_yaml(text, str(path))
    if not isinstance(mapping, dict):
        raise ConfigError(
            f'{path}: expected a mapping at the top level, got {type(mapping).__name__}'
        )
    return mapping


def _number_text(value: float) -> str:
    """A range end for messages: whole numbers in full (4294967295), others as %g."""
    if float(value).is_integer() and abs(value) < 1e19:
        return str(int(value))
    return f'{value:g}'


def describe_range(
    low: float | None, high: float | None, *, low_open: bool = False, high_open: bool = False
) -> str:
    """An allowed range in words for messages: 'in (0, 86400]', '>= 0', '' (unbounded)."""
    if low is not None and high is not None:
        left, right = '(' if low_open else '[', ')' if high_open else ']'
        return f'in {left}{_number_text(low)}, {_number_text(high)}{right}'
    if low is not None:
        return f'{">" if low_open else ">="} {_number_text(low)}'
    if high is not None:
        return f'{"<" if high_open else "<="} {_number_text(high)}'
    return ''


def range_problem(
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    integer: bool = False,
) -> str | None:
    """What is wrong with ``value`` as a finite number in a range, or None when it fits.

    E.g. 'must be a finite number in (0, 86400]'; bool is no number, NaN and inf never fit.
    """
    allowed = describe_range(low, high, low_open=low_open, high_open=high_open)
    kind = ' '.join(filter(None, ('an integer' if integer else 'a finite number', allowed)))
    if isinstance(value, bool) or not isinstance(value, (int,) if integer else (int, float)):
        # A quoted '0.008' (or a !!str tag) reads as a range problem unless its type is named.
        return f'must be {kind}, not a string' if isinstance(value, str) else f'must be {kind}'
    # An int compares exactly; one beyond the float range is no finite float.
    finite = abs(value) <= sys.float_info.max if isinstance(value, int) else math.isfinite(value)
    inside = finite and not (
        (low is not None and (value <= low if low_open else value < low))
        or (high is not None and (value >= high if high_open else value > high))
    )
    return None if inside else f'must be {kind}'


def finite_number(
    value: Any,
    where: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    integer: bool = False,
) -> float:
    """A config number, finite and in range, as a float (an int where ``integer``).

    Args:
        value: the number read from a file or a parameter (bool is no number).
        where: the file and key (or parameter) named in errors.
        low, high: the allowed range's ends (None: unbounded); ``low_open`` and ``high_open``
            leave an end out.
        integer: the value must be an integer.

    Raises:
        ConfigError: not a number, NaN or inf, or out of range; names the key, the value and
            the allowed range.
    """
    problem = range_problem(
        value, low=low, high=high, low_open=low_open, high_open=high_open, integer=integer
    )
    if problem:
        raise ConfigError(f'{where}: {problem}, got {value!r}{number_hint(value)}')
    return int(value) if integer else float(value)


#: A number followed by a unit ('8ms', '10 Hz', '2.5rad/s'): text where a bare number belongs.
_NUMBER_WITH_UNIT = re.compile(r'\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[^\d\s.+-].*')


def number_hint(value: Any, unit: str = '') -> str:
    """'; <how to write it>' for a string where a config number belongs, else ''.

    A quoted number (``'0.008'``) is written without quotes; a number with a unit (``8ms``)
    as the bare number in ``unit``, else in the unit the key names (``ipo_period_s``: s).
    """
    if not isinstance(value, str):
        return ''
    if _looks_numeric(value):
        return f'; write the number without quotes: {value.strip()}'
    if _NUMBER_WITH_UNIT.fullmatch(value):
        return (
            '; a number with a unit is text, not a number: write the bare number in '
            f'{unit or "the unit the key names"}'
        )
    return ''


def check_keys(
    data: Mapping[str, Any],
    allowed: Sequence[str],
    where: str,
    required: Sequence[str] = (),
) -> None:
    """Reject unknown and missing keys, naming them and where they are.

    Raises:
        ConfigError: a key is unknown or a required key is missing.
    """
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}')
    missing = [key for key in required if key not in data]
    if missing:
        raise ConfigError(f'{where}: missing required key(s) {missing}')


def readonly(array: np.ndarray) -> np.ndarray:
    """Return the array marked read-only, so frozen configs stay frozen."""
    array.flags.writeable = False
    return array


def _looks_numeric(text: str) -> bool:
    """Whether ``text`` reads as a number (a quoted number in YAML)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _word_among_numbers(value: Any) -> object | None:
    """The first str, bytes or bool in ``value`` (a scalar or nested list), or None.

    numpy turns '420' and True into 420.0 and 1.0 without a word; a config that quotes a number
    or writes a flag where a number belongs is refused instead.
    """
    if isinstance(value, (str, bytes, bool, np.bool_)):
        return value
    if isinstance(value, np.ndarray):
        return None if value.dtype.kind in 'iuf' else _word_among_numbers(value.tolist())
    if isinstance(value, (list, tuple)):
        for entry in value:
            word = _word_among_numbers(entry)
            if word is not None:
                return word
    return None


def float_vector(
    value: Any,
    where: str,
    length: int,
    *,
    minimum: float | None = None,
    exclusive_minimum: bool = False,
    each: str = 'one per joint',
) -> np.ndarray:
    """Convert a scalar or list into a read-only float vector of the given length.

    A scalar is broadcast to every entry. ``each``: what the values are, for the message of a
    wrong length ('one per joint'; 'x, y, z of the centre of mass [m]' for a 3-vector).

    Raises:
        ConfigError: wrong length, non-numeric entries (a quoted number such as '420' or a
            bool included), non-finite entries, or a value below the minimum.
    """
    word = _word_among_numbers(value)
    if word is not None:
        context = '' if word is value else f' in {value!r}'
        raise ConfigError(f'{where}: expected numbers, got {word!r}{context}{number_hint(word)}')
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ConfigError(f'{where}: expected numbers, got {value!r}') from err
    if array.ndim == 0:
        array = np.full(length, float(array))
    if array.shape != (length,):
        raise ConfigError(f'{where}: expected {length} values ({each}), got {value!r}')
    if not np.all(np.isfinite(array)):
        raise ConfigError(f'{where}: values must be finite, got {value!r}')
    if minimum is not None:
        bad = array <= minimum if exclusive_minimum else array < minimum
        if np.any(bad):
            relation = '>' if exclusive_minimum else '>='
            raise ConfigError(f'{where}: every value must be {relation} {minimum}, got {value!r}')
    return readonly(array)


#: The characters of a ROS 2 topic name as written, and of one fully expanded.
_TOPIC_CHARACTERS = re.compile(r'[A-Za-z0-9_/~{}]*')
_FULL_TOPIC = re.compile(r'(/[A-Za-z_][A-Za-z0-9_]*)+')
_SUBSTITUTION = re.compile(r'\{([^{}]*)\}')
_SUBSTITUTIONS = {'node': 'node', 'ns': '/ns', 'namespace': '/ns'}
#: rmw's limit on a fully qualified topic name (RMW_TOPIC_MAX_NAME_LENGTH).
TOPIC_MAX_LENGTH = 247


def topic_name_problem(name: object) -> str | None:
    """Why ``name`` is no valid ROS 2 topic name, or None when it is one.

    The rules of ``rcl_validate_topic_name``, then those of ``rmw_validate_full_topic_name`` on
    the name expanded for a node ``node`` in a namespace ``/ns`` (``~``, ``{node}``, ``{ns}``
    substituted): what rclpy checks when a node creates a publisher or subscription, here
    without importing ROS (the core reads topic names from configs).
    ``test/ros/test_topic_names.py`` holds the two equal.
    """
    if not isinstance(name, str):
        return f'a topic name is a string, got {name!r}'
    if not name:
        return 'a topic name must not be empty'
    if not _TOPIC_CHARACTERS.fullmatch(name):
        return "a topic name holds only letters, digits, '_', '/', '~', '{' and '}'"
    if name.endswith('/'):
        return "a topic name must not end with '/'"
    if '~' in name[1:]:
        return "'~' may only be a topic name's first character"
    if name.startswith('~') and len(name) > 2 and name[1] != '/':  # rcl lets '~x' pass
        return "'~' must be followed by '/'"
    if '{' in _SUBSTITUTION.sub('', name) or '}' in _SUBSTITUTION.sub('', name):
        return "a topic name's curly braces must be balanced"
    for substitution in _SUBSTITUTION.findall(name):
        if substitution not in _SUBSTITUTIONS:
            return (
                f'unknown substitution {{{substitution}}}; known: {{node}}, {{ns}}, {{namespace}}'
            )
    expanded = '/ns/node' + name[1:] if name.startswith('~') else name
    expanded = _SUBSTITUTION.sub(lambda found: _SUBSTITUTIONS[found.group(1)], expanded)
    expanded = expanded if expanded.startswith('/') else f'/ns/{expanded}'
    if '//' in expanded:
        return "a topic name must not hold '//'"
    if not _FULL_TOPIC.fullmatch(expanded):
        return 'a topic name token (between slashes) must not start with a digit'
    if len(expanded) > TOPIC_MAX_LENGTH:
        return f'a topic name is at most {TOPIC_MAX_LENGTH} characters long'
    return None


class DuplicateKeyError(ValueError):
    """A JSON object names one key twice (``loads_unique``); the message names the key.

    Attributes:
        key: the key given twice.
        values: its two values, as short JSON texts.
    """

    def __init__(self, key: str, values: tuple[str, str]) -> None:
        super().__init__(
            f'key {key!r} appears twice in one object ({values[0]} and {values[1]}): which one '
            'holds is ambiguous'
        )
        self.key = key
        self.values = values


def _unique_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict; refuses a key given twice.

    Raises:
        DuplicateKeyError: names the key and its two values.
    """
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise DuplicateKeyError(key, (short_json(out[key]), short_json(value)))
        out[key] = value
    return out


def broken_link(path: Path | str) -> str | None:
    """What ``path`` is when it is a symbolic link that leads to nothing, for messages.

    'a link to <target>, which does not exist' (or, for a chain of links, that the chain ends
    nowhere); None for anything else: a file, a folder, a link to one, or no entry at all. A
    reader that says 'no such file' of a dangling link sends the user looking for the wrong
    thing: the link is there, its target is not.
    """
    try:
        target = os.readlink(path)
    except OSError:  # no link, or no entry at all
        return None
    if os.path.exists(path):
        return None
    if os.path.lexists(os.path.join(os.path.dirname(path), target)):
        return f'a link to {target}, a chain of links that leads to nothing'
    return f'a link to {target}, which does not exist'


def short_json(value: Any) -> str:
    """``value`` as JSON, cut to 40 characters (for messages)."""
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + '...'


def loads_unique(text: str) -> Any:
    """``json.loads`` that refuses an object with a key given twice (the stdlib keeps the last).

    Raises:
        DuplicateKeyError: a key repeats within one object (the message names it).
        json.JSONDecodeError: not valid JSON.
    """
    return json.loads(text, object_pairs_hook=_unique_object)
