"""The schema of node parameters: fields with ROS metadata, checked, declared and read.

A node's parameters are one frozen dataclass whose fields come from ``param``: each carries its
ROS description (with units), whether it is read-only at runtime, and what it may hold:
``choices`` (an enumeration), ``low``/``high`` (a finite number in that range: NaN and inf never
pass) or ``topic`` (a ROS topic name, by the rules rclpy applies, checked without importing ROS:
``config_io.topic_name_problem``). The dataclass's ``__post_init__`` calls ``check_schema`` and
adds the rules that tie fields together. ``declare_parameters`` declares every field,
``read_snapshot`` reads one validated snapshot (errors name the node, the parameter and the
value), ``validate_change`` checks a runtime change by building a new snapshot, and
``load_node_config`` reads a ROS 2 parameter file without ROS.

This module imports rclpy only inside the functions that talk to a node.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, get_type_hints

from id_learning.config_io import (
    describe_range,
    load_yaml_mapping,
    range_problem,
    topic_name_problem,
)
from id_learning.errors import ConfigError

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = [
    'check_schema',
    'config_from_mapping',
    'constraints',
    'declare_parameters',
    'load_node_config',
    'param',
    'read_snapshot',
    'validate_change',
]

_T = TypeVar('_T')


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


def check_schema(config: object) -> None:
    """Check every field against its schema: choices, finite numbers in range, topic names.

    Raises:
        ConfigError: names the parameter, the value and what it may hold.
    """
    for item in dataclasses.fields(config):  # type: ignore[arg-type]
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
        raise ConfigError(f'{path}: no {node}: ros__parameters: section')
    values = dict(section['ros__parameters'])
    values = {key: value for key, value in values.items() if key != 'use_sim_time'}
    return config_from_mapping(cls, values, f'{path}: {node}')


# -- ROS ----------------------------------------------------------------------------------------
def declare_parameters(node: Node, cls: type) -> None:
    """Declare every field of a node config as a parameter with its description and default."""
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    types = _field_types(cls)
    ros_types = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
        tuple[str, ...]: ParameterType.PARAMETER_STRING_ARRAY,
    }
    for item in dataclasses.fields(cls):
        kind = types[item.name]
        default = item.default
        descriptor = ParameterDescriptor(
            name=item.name,
            type=ros_types[kind],
            description=item.metadata['description'],
            read_only=item.metadata['read_only'],
            # A YAML '1' for a float parameter is an integer: accept it and convert on reading.
            dynamic_typing=kind is float,
        )
        descriptor.additional_constraints = constraints(item)
        try:
            node.declare_parameter(
                item.name, list(default) if isinstance(default, tuple) else default, descriptor
            )
        except (InvalidParameterTypeException, InvalidParameterValueException) as err:
            given = getattr(node, '_parameter_overrides', {}).get(item.name)
            value = given.value if given is not None else '?'
            raise ConfigError(
                f'node {node.get_name()}: {item.name}: {value!r} is no {kind_name(kind)} '
                f'({item.metadata["description"]})'
            ) from err
    refuse_unknown(node, cls)
    node.add_pre_set_parameters_callback(lambda changes: _refuse_undeclared(node, cls, changes))


def _refuse_undeclared(node: Node, cls: type, changes: list[Any]) -> list[Any]:
    """Refuse setting a parameter the node does not have, at runtime, naming it.

    rclpy's own refusal names none (its list of undeclared names comes out empty).

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
    return changes


def _hinted(unknown: list[str], known: list[str]) -> str:
    """The unknown names, each with the closest known one."""
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(name, sorted(known), n=1)
        hints.append(f'{name} (did you mean {close[0]}?)' if close else name)
    return ', '.join(hints)


def kind_name(kind: object) -> str:
    """How a parameter's type reads in a message."""
    names = {bool: 'boolean', int: 'integer', float: 'number', str: 'string'}
    return names.get(kind, 'list of strings')  # type: ignore[call-overload]


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
    values = {
        item.name: node.get_parameter(item.name).value
        for item in dataclasses.fields(cls)  # type: ignore[arg-type]
    }
    return config_from_mapping(cls, values, f'node {node.get_name()}')


def validate_change(current: _T, changes: Mapping[str, Any]) -> tuple[_T | None, str]:
    """A new snapshot with ``changes`` applied, or None and the reason to reject them."""
    types = _field_types(type(current))
    metadata = {item.name: item.metadata for item in dataclasses.fields(current)}  # type: ignore[arg-type]
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
        return dataclasses.replace(current, **updates), ''  # type: ignore[type-var]
    except ConfigError as err:
        return None, str(err)
