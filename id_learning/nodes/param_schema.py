"""The schema of node parameters: fields with ROS metadata, checked, declared and read.

A node's parameters are one frozen dataclass whose fields come from ``param``: each carries its
ROS description (with units), whether it is read-only at runtime, and what it may hold:
``choices`` (an enumeration), ``low``/``high`` (a finite number in that range: NaN and inf never
pass) or ``topic`` (a ROS topic name, by the rules rclpy applies, checked without importing ROS:
``config_io.topic_name_problem``). The dataclass's ``__post_init__`` calls ``check_schema`` and
adds the rules that tie fields together. ``declare_parameters`` declares every field,
``read_snapshot`` reads one validated snapshot (errors name the node, the parameter and the
value), ``read_node_config`` reads one before the node is made (to build what the node is
given), ``validate_change`` checks a runtime change by building a new snapshot, and
``load_node_config`` reads a ROS 2 parameter file without ROS.

This module imports rclpy only inside the functions that talk to a node.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, get_type_hints

import yaml

from id_learning.config_io import (
    describe_range,
    load_yaml_mapping,
    range_problem,
    read_capped,
    topic_name_problem,
)
from id_learning.errors import ConfigError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance
    from rclpy.node import Node

__all__ = [
    'check_schema',
    'config_from_mapping',
    'constraints',
    'declare_parameters',
    'load_node_config',
    'param',
    'params_file_problem',
    'params_files',
    'read_node_config',
    'read_snapshot',
    'refuse_foreign_params_files',
    'section_matches',
    'shared_topic_problem',
    'validate_change',
]

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
        },
    )


def constraints(item: dataclasses.Field[Any]) -> str:
    """A field's allowed values in words ('one of [...]', 'in (0, 1]', 'a ROS topic name')."""
    if item.metadata.get('choices'):
        return f'one of {list(item.metadata["choices"])}'
    if item.metadata.get('range'):
        low, high, low_open, high_open = item.metadata['range']
        return describe_range(low, high, low_open=low_open, high_open=high_open)
    return 'a ROS topic name' if item.metadata.get('topic') else ''


def check_schema(config: DataclassInstance) -> None:
    """Check every field against its schema: choices, finite numbers in range, topic names.

    Raises:
        ConfigError: names the parameter, the value and what it may hold.
    """
    for item in dataclasses.fields(config):
        value = getattr(config, item.name)
        choices = item.metadata.get('choices')
        if choices and value not in choices:
            raise ConfigError(f'{item.name} must be one of {list(choices)}, got {value!r}')
        bounds = item.metadata.get('range')
        if bounds is not None:
            low, high, low_open, high_open = bounds
            problem = range_problem(
                value,
                low=low,
                high=high,
                low_open=low_open,
                high_open=high_open,
                integer=_field_types(type(config))[item.name] is int,
            )
            if problem:
                raise ConfigError(f'{item.name}: {problem}, got {value!r}')
        if item.metadata.get('topic'):
            for name in value if isinstance(value, tuple | list) else (value,) if value else ():
                problem = topic_name_problem(name)
                if problem:
                    raise ConfigError(f'{item.name}: {name!r} is no ROS topic name: {problem}')


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


_FIELD_TYPES: dict[type, dict[str, Any]] = {}


def _field_types(cls: type) -> dict[str, Any]:
    """The fields' types of a node config class (resolved once per class)."""
    if cls not in _FIELD_TYPES:
        _FIELD_TYPES[cls] = get_type_hints(cls)
    return _FIELD_TYPES[cls]


def _coerce(name: str, kind: Any, value: Any) -> Any:
    """A parameter value as the dataclass field's type, or ConfigError."""
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == tuple[str, ...]:
        if isinstance(value, (list, tuple)) and all(isinstance(item, str) for item in value):
            return tuple(value)
    elif isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    raise ConfigError(f'{name}: expected {getattr(kind, "__name__", kind)}, got {value!r}')


def config_from_mapping(cls: type[_T], values: Mapping[str, Any], where: str) -> _T:
    """Build a node config from parameter values; unknown keys and wrong types name the key.

    Raises:
        ConfigError: unknown key, wrong type or a value out of range.
    """
    types = _field_types(cls)
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
    words = list(sys.argv[1:] if args is None else args)
    files, is_ros = [], False
    for index, word in enumerate(words):
        if word in ('--ros-args', '--'):
            is_ros = word == '--ros-args'
        elif is_ros and word == '--params-file' and index + 1 < len(words):
            files.append(Path(words[index + 1]))
    return files


#: The arguments ``runtime.run_node`` gave rclpy.init (None: ``sys.argv``): their params files.
COMMAND_LINE: list[str] | None = None


def refuse_foreign_params_files(node: Node, args: Sequence[str] | None = None) -> None:
    """Refuse a ``--params-file`` with no section for this node (a misspelt ``recordr:``).

    rcl skips such a file without a word: the node would run on its defaults, a recorder
    recording the default topics to the default folder.

    Args:
        args: the command line; None: ``COMMAND_LINE``.

    Raises:
        ConfigError: names the file, its sections and the node, with the closest section.
    """
    for path in params_files(COMMAND_LINE if args is None else args):
        try:
            data = yaml.safe_load(read_capped(path, 'parameter file').decode('utf-8'))
        except (ConfigError, OSError, UnicodeDecodeError, yaml.YAMLError):
            continue  # rcl read it before the node started; nothing to add here
        problem = params_file_problem(path, data, node.get_name(), node.get_namespace())
        if problem:
            raise ConfigError(f'node {node.get_name()}: {problem}')


# -- ROS ----------------------------------------------------------------------------------------
def declare_parameters(node: Node, cls: type, values: object | None = None) -> None:
    """Declare every field of a node config as a parameter with its description and default.

    Args:
        values: a snapshot (a ``cls``) read before the node was made (``read_node_config``): its
            values are declared, in place of the defaults and of the overrides the node was
            given, which that snapshot already holds.

    Raises:
        ConfigError: a params file with no section for the node, a value of the wrong type, or
            a parameter the node does not have.
    """
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    if values is None:
        refuse_foreign_params_files(node)
    types = _field_types(cls)
    ros_types = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
        tuple[str, ...]: ParameterType.PARAMETER_STRING_ARRAY,
    }
    overrides = getattr(node, '_parameter_overrides', {})
    for item in dataclasses.fields(cls):
        kind = types[item.name]
        default = item.default if values is None else getattr(values, item.name)
        if kind is float and item.name in overrides:  # a YAML '1': declared as the double 1.0
            overrides[item.name] = _as_double(overrides[item.name])
        descriptor = ParameterDescriptor(
            name=item.name,
            type=ros_types[kind],
            description=item.metadata['description'],
            read_only=item.metadata['read_only'],
            # A YAML '1' for a float parameter is an integer: converted to a double (above, and
            # at runtime in _before_set); other types reach the snapshot, which names them.
            dynamic_typing=kind is float,
        )
        descriptor.additional_constraints = constraints(item)
        try:
            node.declare_parameter(
                item.name,
                list(default) if isinstance(default, tuple) else default,
                descriptor,
                ignore_override=values is not None,
            )
        except (InvalidParameterTypeException, InvalidParameterValueException) as err:
            given = getattr(node, '_parameter_overrides', {}).get(item.name)
            value = given.value if given is not None else '?'
            raise ConfigError(
                f'node {node.get_name()}: {item.name}: {value!r} is no {kind_name(kind)} '
                f'({item.metadata["description"]})'
            ) from err
    if values is None:
        refuse_unknown(node, cls)
    node.add_pre_set_parameters_callback(lambda changes: _before_set(node, cls, changes))


def read_node_config(
    name: str,
    cls: type[_T],
    check: Callable[[Node, _T], None] | None = None,
    **node_options: Any,
) -> _T:
    """A node's parameters, read before the node is made: what it needs can be built first.

    A node named ``name`` lives while they are read: its parameters come from where the real
    node's will (the command line's ``-p`` and ``--params-file``, ``parameter_overrides`` in
    ``node_options``), validated as ``read_snapshot`` does, and ``check(node, config)`` runs
    with the node's names and remappings (e.g. resolving its topics). It starts no parameter
    services and writes nothing to /rosout. The real node then declares the snapshot it gets
    (``declare_parameters(node, cls, values=config)``).

    Raises:
        ConfigError: as ``declare_parameters``, ``read_snapshot`` and ``check``.
    """
    from rclpy.node import Node

    node = Node(
        name, **{**node_options, 'start_parameter_services': False, 'enable_rosout': False}
    )
    try:
        declare_parameters(node, cls)
        config = read_snapshot(node, cls)
        if check is not None:
            check(node, config)
        return config
    finally:
        node.destroy_node()


def _as_double(given: Any) -> Any:
    """An integer rclpy Parameter as the double of the same value; any other as it is."""
    from rclpy.parameter import Parameter

    if given.type_ != Parameter.Type.INTEGER:
        return given
    return Parameter(given.name, Parameter.Type.DOUBLE, float(given.value))


def _before_set(node: Node, cls: type, changes: list[Any]) -> list[Any]:
    """Refuse an undeclared parameter at runtime, naming it; an int for a float becomes a double.

    rclpy's own refusal names none (its list of undeclared names comes out empty). An integer
    for a float parameter (``ros2 param set`` sends 1 as one) becomes the double of the same
    value, so that the parameter keeps its type DOUBLE.

    Raises:
        ParameterNotDeclaredException: names each undeclared parameter and the closest one.
    """
    from rclpy.exceptions import ParameterNotDeclaredException

    unknown = sorted(change.name for change in changes if not node.has_parameter(change.name))
    if unknown:
        known = [item.name for item in dataclasses.fields(cls)]
        raise ParameterNotDeclaredException(
            f'{_hinted(unknown, known)} on node {node.get_name()} (its parameters: '
            f'{", ".join(sorted(known))})'
        )
    types = _field_types(cls)
    return [
        _as_double(change) if types.get(change.name) is float else change for change in changes
    ]


def _hinted(unknown: list[str], known: list[str]) -> str:
    """The unknown names, each with the closest known one."""
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(name, sorted(known), n=1)
        hints.append(f'{name} (did you mean {close[0]}?)' if close else name)
    return ', '.join(hints)


def kind_name(kind: object) -> str:
    """How a parameter's type reads in a message."""
    names: dict[object, str] = {bool: 'boolean', int: 'integer', float: 'number', str: 'string'}
    return names.get(kind, 'list of strings')


#: Parameters every rclpy node takes besides its own.
_ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')


def refuse_unknown(node: Node, cls: type) -> None:
    """Refuse a parameter given to the node that it does not have, naming the closest one.

    rclpy keeps an undeclared override without a word: a misspelt name would be ignored.

    Raises:
        ConfigError: names every unknown parameter.
    """
    known = {item.name for item in dataclasses.fields(cls)}
    given = getattr(node, '_parameter_overrides', {})
    unknown = sorted(
        name
        for name in given
        if name not in known
        and name not in _ROS_PARAMETERS
        and not name.startswith('qos_overrides.')
    )
    if not unknown:
        return
    raise ConfigError(
        f'node {node.get_name()}: unknown parameter(s) {_hinted(unknown, list(known))}; its '
        f'parameters: {", ".join(sorted(known))}'
    )


def read_snapshot(node: Node, cls: type[_T]) -> _T:
    """Read every declared field of a node config into one validated snapshot.

    Raises:
        ConfigError: a value has the wrong type or is out of range (names the parameter).
    """
    values = {item.name: node.get_parameter(item.name).value for item in dataclasses.fields(cls)}
    return config_from_mapping(cls, values, f'node {node.get_name()}')


def validate_change(current: _T, changes: Mapping[str, Any]) -> tuple[_T | None, str]:
    """A new snapshot with ``changes`` applied, or None and the reason to reject them."""
    types = _field_types(type(current))
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
