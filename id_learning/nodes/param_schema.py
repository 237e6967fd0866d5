"""The schema of node parameters: fields with ROS metadata, checked without ROS.

A node's parameters are one frozen dataclass whose fields come from ``param``: each carries its
ROS description (with units), whether it is read-only at runtime, and what it may hold:
``choices`` (an enumeration), ``low``/``high`` (a finite number in that range: NaN and inf never
pass) or ``topic`` (a ROS topic name, by the rules rclpy applies, checked without importing ROS:
``config_io.topic_name_problem``). The dataclass's ``__post_init__`` calls ``check_schema`` and
adds the rules that tie fields together. ``value_problem`` checks one value alone (a value given
on the command line, before ROS merges it with the others), ``validate_change`` checks a runtime
change by building a new snapshot, ``load_node_config`` reads a ROS 2 parameter file, and
``command_line_sources`` lists where a command line gives parameters (``-p``, ``--params-file``).

This module imports no ROS: ``nodes.param_ros`` declares, reads and checks parameters on a node.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, get_type_hints

from id_learning.config_io import (
    describe_range,
    load_yaml_mapping,
    range_problem,
    topic_name_problem,
)
from id_learning.errors import ConfigError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    'MAX_SECONDS',
    'STRING_LIST',
    'check_schema',
    'command_line_sources',
    'config_from_mapping',
    'constraints',
    'field_types',
    'kind_name',
    'load_node_config',
    'param',
    'params_file_problem',
    'params_files',
    'refuse_shared_topics',
    'section_matches',
    'shared_topic_problem',
    'validate_change',
    'value_problem',
]

#: The type of a list parameter (topics, msg_types).
STRING_LIST = tuple[str, ...]
#: The longest time a parameter may give [s], about 32 years: every time parameter has a ``high``
#: at most this, so that its nanoseconds fit an int64 where the node or rclpy converts them.
MAX_SECONDS = 1e9
#: Groups of (topic by parameter, what the node uses its own fixed topics for), see topic_checks.
TopicChecks = list[tuple[dict[str, str], dict[str, str]]]

_T = TypeVar('_T', bound='DataclassInstance')


def param(
    default: Any,
    description: str,
    *,
    read_only: bool = True,
    choices: tuple[str, ...] | None = None,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    topic: bool = False,
    non_empty: str = '',
    unique: bool = False,
    msg_type: bool = False,
    zero_or_at_least: tuple[float, str, str] | None = None,
) -> Any:
    """A dataclass field with the metadata of a ROS parameter and what it may hold.

    Args:
        default: the value when the parameter is not set.
        description: what it does, with its unit.
        read_only: whether a change at runtime is refused.
        choices: the values an enumeration allows.
        low, high, low_open, high_open: the range of a number (None: unbounded); NaN and inf
            are always refused.
        topic: a ROS topic name (each item of a list; an empty string means off).
        non_empty: for a list that may not be empty, what to give instead ('' : it may be).
        unique: a list whose items may not repeat.
        msg_type: a ROS message type, pkg/msg/Type (each item of a list).
        zero_or_at_least: (least, what 0 means, unit): a number that is 0 or at least ``least``.
    """
    bounds = None if low is None and high is None else (low, high, low_open, high_open)
    if choices:
        description = f'{description} One of {list(choices)}.'
    return field(
        default=default,
        metadata={
            'description': description,
            'read_only': read_only,
            'choices': choices,
            'range': bounds,
            'topic': topic,
            'non_empty': non_empty,
            'unique': unique,
            'msg_type': msg_type,
            'zero_or_at_least': zero_or_at_least,
        },
    )


def constraints(item: dataclasses.Field[Any]) -> str:
    """A field's allowed values in words ('one of [...]', 'in (0, 1]', 'a ROS topic name')."""
    if item.metadata.get('choices'):
        return f'one of {list(item.metadata["choices"])}'
    if item.metadata.get('range'):
        low, high, low_open, high_open = item.metadata['range']
        text = describe_range(low, high, low_open=low_open, high_open=high_open)
        least = item.metadata.get('zero_or_at_least')
        return text if least is None else f'{text}, 0 ({least[1]}) or at least {least[0]:g}'
    return 'a ROS topic name' if item.metadata.get('topic') else ''


def check_schema(config: DataclassInstance) -> None:
    """Check every field against its schema: choices, finite numbers in range, topic names.

    Raises:
        ConfigError: names the parameter, the value and what it may hold.
    """
    for item in dataclasses.fields(config):
        problem = _schema_problem(item, getattr(config, item.name), field_types(type(config)))
        if problem:
            raise ConfigError(problem)


def _schema_problem(item: dataclasses.Field[Any], value: Any, types: Mapping[str, Any]) -> str:
    """What is wrong with a field's value by its schema ('' if nothing), naming the field."""
    items = value if isinstance(value, tuple | list) else (value,)
    if item.metadata.get('non_empty') and isinstance(value, tuple | list) and not value:
        return f'{item.name}: an empty list; {item.metadata["non_empty"]}'
    if item.metadata.get('unique') and len(set(items)) != len(items):
        return f'{item.name} lists an entry twice: {list(items)}'
    for entry in items if item.metadata.get('msg_type') else ():
        if not isinstance(entry, str) or entry.count('/') != 2:
            return f'{item.name}: expected pkg/msg/Type, got {entry!r}'
    choices = item.metadata.get('choices')
    if choices and value not in choices:
        return f'{item.name} must be one of {list(choices)}, got {value!r}'
    bounds = item.metadata.get('range')
    if bounds is not None:
        low, high, low_open, high_open = bounds
        problem = range_problem(
            value,
            low=low,
            high=high,
            low_open=low_open,
            high_open=high_open,
            integer=types[item.name] is int,
        )
        if problem:
            return f'{item.name}: {problem}, got {value!r}'
    least = item.metadata.get('zero_or_at_least')
    if least is not None and 0 < value < least[0]:
        minimum, zero, unit = least
        return f'{item.name}: must be 0 ({zero}) or at least {minimum:g} {unit}, got {value!r}'
    if item.metadata.get('topic'):
        for name in value if isinstance(value, tuple | list) else (value,) if value else ():
            problem = topic_name_problem(name)
            if problem:
                return f'{item.name}: {name!r} is no ROS topic name: {problem}'
    return ''


def value_problem(cls: type, name: str, value: Any) -> str:
    """What is wrong with one value of parameter ``name`` alone ('' if nothing), naming it.

    Its type (an integer for a float is converted), then its field's schema; the rules between
    fields need the whole snapshot and are not checked here.
    """
    kind = field_types(cls)[name]
    item = next(item for item in dataclasses.fields(cls) if item.name == name)
    try:
        value = _coerce(name, kind, value)
    except ConfigError:
        return f'{name}: {value!r} is no {kind_name(kind)} ({item.metadata["description"]})'
    return _schema_problem(item, value, field_types(cls))


def kind_name(kind: object) -> str:
    """How a parameter's type reads in a message."""
    names: dict[object, str] = {bool: 'boolean', int: 'integer', float: 'number', str: 'string'}
    return names.get(kind, 'list of strings')


def shared_topic_problem(named: Mapping[str, str], own: Mapping[str, str]) -> str | None:
    """Two parameters naming one topic, or one naming a topic the node keeps; None if neither.

    One node cannot publish and subscribe different types on one topic (rcl refuses it with a
    misleading error), and with one type it would feed on its own output.

    Args:
        named: topic of each parameter in use (as written, or resolved by the node).
        own: what the node itself uses each of its fixed topics for (``/diagnostics``, ...).
    """
    seen: dict[str, str] = {}
    for parameter, topic in named.items():
        if topic in own:
            return f"{parameter} {topic!r} is the topic of the node's {own[topic]}: choose another"
        if topic in seen:
            return (
                f'{seen[topic]} and {parameter} both name topic {topic!r}: each needs its own '
                '(on one, the node would mix the two, refuse them, or feed on its own output)'
            )
        seen[topic] = parameter
    return None


class _HasTopics(Protocol):
    """A node config that says which of its topics may not meet (``topic_checks``)."""

    def topic_checks(self) -> TopicChecks: ...


def refuse_shared_topics(
    config: _HasTopics, resolve: Callable[[str], str] | None = None, where: str = ''
) -> None:
    """Refuse two topic parameters of a node on one topic, or one on a topic the node keeps.

    Args:
        config: the node's parameters (``topic_checks`` says which topics may not meet).
        resolve: the node's name resolution (namespace, remaps); None: as written, where only
            equal strings are surely one topic ('tau_u' and '/tau_u' are one in the root
            namespace only: the node checks again with the resolved names).
        where: put before the reason (the node).

    Raises:
        ConfigError: names both parameters (or the parameter and the node's use) and the topic.
    """
    name = resolve or (lambda topic: topic)
    for named, own in config.topic_checks():
        problem = shared_topic_problem(
            {parameter: name(topic) for parameter, topic in named.items()},
            {name(topic): what for topic, what in own.items()},
        )
        if problem:
            raise ConfigError(f'{where}{problem}')


_FIELD_TYPES: dict[type, dict[str, Any]] = {}


def field_types(cls: type) -> dict[str, Any]:
    """The fields' types of a node config class (resolved once per class)."""
    if cls not in _FIELD_TYPES:
        _FIELD_TYPES[cls] = get_type_hints(cls)
    return _FIELD_TYPES[cls]


def _coerce(name: str, kind: Any, value: Any) -> Any:
    """A parameter value as the dataclass field's type, or ConfigError."""
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == STRING_LIST:
        if isinstance(value, (list, tuple)) and all(isinstance(item, str) for item in value):
            return tuple(value)
    elif isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    raise ConfigError(f'{name}: {value!r} is no {kind_name(kind)}')


def config_from_mapping(cls: type[_T], values: Mapping[str, Any], where: str) -> _T:
    """Build a node config from parameter values; unknown keys and wrong types name the key.

    Raises:
        ConfigError: unknown key, wrong type or a value out of range.
    """
    types = field_types(cls)
    unknown = sorted(set(values) - set(types))
    if unknown:
        raise ConfigError(f'{where}: unknown parameter(s) {unknown}; known: {sorted(types)}')
    try:
        return cls(**{name: _coerce(name, types[name], value) for name, value in values.items()})
    except ConfigError as err:
        raise ConfigError(f'{where}: {err}') from None


def load_node_config(path: Path | str, node: str, cls: type[_T]) -> _T:
    """Read one node's ``ros__parameters`` from a ROS 2 parameter file.

    Raises:
        ConfigError: the file or the node's section is missing or invalid.
    """
    path = Path(path)
    data = load_yaml_mapping(path)
    section = data.get(node) or data.get(f'/{node}') or data.get('/**')
    if not isinstance(section, Mapping) or not isinstance(section.get('ros__parameters'), Mapping):
        problem = params_file_problem(path, data, node)
        raise ConfigError(problem or f'{path}: no {node}: ros__parameters: section')
    values = dict(section['ros__parameters'])
    values = {key: value for key, value in values.items() if key != 'use_sim_time'}
    return config_from_mapping(cls, values, f'{path}: {node}')


def section_matches(key: str, node: str, namespace: str = '/') -> bool:
    """Whether a parameter file's top-level key applies to a node, by rcl's rules.

    A key is a node's name, its fully qualified name, or a pattern of it where ``*`` stands
    for one name token and ``**`` for any number (``/**`` is every node); a key without a
    leading slash is taken from the root. The bare name is accepted in any namespace.
    """
    fqn = f'{namespace.rstrip("/")}/{node}'
    if key in (node, fqn):
        return True
    parts = []
    for token in (key if key.startswith('/') else f'/{key}').split('/')[1:]:
        if token == '**':
            parts.append('(?:/[^/]+)*')
        else:
            parts.append('/' + '[^/]*'.join(re.escape(piece) for piece in token.split('*')))
    return re.fullmatch(''.join(parts), fqn) is not None


def params_file_problem(path: Path, data: object, node: str, namespace: str = '/') -> str | None:
    """Why a parameter file given to a node sets none of its parameters, or None.

    rcl applies only the sections whose key matches the node; a misspelt key (``recordr:``) is
    skipped without a word and the node would run on its defaults.
    """
    if not isinstance(data, Mapping) or not data:
        return None  # rcl read it before the node started: nothing of ours to add
    keys = [str(key) for key in data]
    if any(section_matches(key, node, namespace) for key in keys):
        return None
    fqn = f'{namespace.rstrip("/")}/{node}'
    leaves = {key.rstrip('/').rsplit('/', 1)[-1]: key for key in keys}
    close = difflib.get_close_matches(node, sorted(leaves), n=1, cutoff=0.6)
    hint = f' (did you mean {node} for {leaves[close[0]]}?)' if close else ''
    return (
        f'{path}: no section of it is for node {fqn}{hint}: its sections are {keys}, so the node '
        f'would run on its defaults; name the section {node}: (or /**: for every node)'
    )


def params_files(args: Sequence[str] | None) -> list[Path]:
    """The ``--params-file`` files of a command line (None: ``sys.argv``), in its ROS part."""
    return [
        Path(words[1]) for _, words in command_line_sources(args) if words[0] == '--params-file'
    ]


#: ROS arguments that take a value (skipped over when looking for parameters).
_WITH_VALUE = frozenset(
    {'-r', '--remap', '-e', '--enclave', '--log-level', '--log-config-file', '--log-file-name'}
)


def command_line_sources(args: Sequence[str] | None) -> list[tuple[str, list[str]]]:
    """Where a command line (None: ``sys.argv``) gives parameters, in its order.

    Each is (how it reads, e.g. ``-p rate:=fast`` or ``--params-file nodes.yaml``; its ROS
    arguments, e.g. ``['-p', 'rate:=fast']``), from the ``--ros-args`` parts only.
    """
    words = list(sys.argv[1:] if args is None else args)
    sources: list[tuple[str, list[str]]] = []
    is_ros, index = False, 0
    while index < len(words):
        word = words[index]
        if word in ('--ros-args', '--'):
            is_ros = word == '--ros-args'
        elif is_ros and index + 1 < len(words):
            if word in ('-p', '--param', '--params-file'):
                flag = '--params-file' if word == '--params-file' else '-p'
                sources.append((f'{flag} {words[index + 1]}', [flag, words[index + 1]]))
                index += 1
            elif word in _WITH_VALUE:
                index += 1
        index += 1
    return sources


def validate_change(current: _T, changes: Mapping[str, Any]) -> tuple[_T | None, str]:
    """A new snapshot with ``changes`` applied, or None and the reason to reject them."""
    types = field_types(type(current))
    metadata = {item.name: item.metadata for item in dataclasses.fields(current)}
    updates = {}
    for name, value in changes.items():
        if name not in metadata:
            continue  # not ours (use_sim_time and the like)
        if metadata[name]['read_only']:
            return None, f'{name} is read-only at runtime'
        try:
            updates[name] = _coerce(name, types[name], value)
        except ConfigError as err:
            return None, str(err)
    try:
        return dataclasses.replace(current, **updates), ''
    except ConfigError as err:
        return None, str(err)


def log_change(logger: Any, before: DataclassInstance, after: DataclassInstance) -> None:
    """Warn of every parameter a runtime set changed, before and after, in one line.

    A gate loosened at runtime (``consistency_scale``, ``rearm_samples``, ``max_age_s``) changes
    what the node lets through: the log says who changed what, not only /parameter_events.
    """
    changed = [
        f'{item.name} {getattr(before, item.name)!r} -> {getattr(after, item.name)!r}'
        for item in dataclasses.fields(before)
        if getattr(before, item.name) != getattr(after, item.name)
    ]
    if changed:
        logger.warning(f'parameters set at runtime: {", ".join(changed)}')
