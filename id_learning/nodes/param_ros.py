"""Node parameters on a ROS node: declared from the schema, read as one snapshot, checked as given.

``declare_parameters`` declares every field of a node config (``nodes.param_schema``) with its
description and constraints; before that it refuses what ROS would take without a word:

- a ``--params-file`` that is no regular file (a FIFO, ``<(...)``, a device: ``params_file_kind``,
  checked before ROS starts), one that repeats a key in one mapping (rcl keeps the later value
  without a word; the package's other YAML readers refuse it) or that is no valid YAML, and one
  with no section for the node (``refuse_foreign_params_files``);
- a value given on the command line that the node could not use, even one a later ``-p`` or file
  replaces (``check_given_values``); and rcl keeps the first of two values of one parameter when
  the later one has another type (``-p rate:=10.0 -p rate:=fast`` played at 10): the node holds
  the last value given, as ROS 2 documents;
- ``[]``, which ROS reads as a value of no type: an empty list for a list parameter (the
  schema then says whether one may be empty), refused by name for any other;
- a parameter the node does not have (``refuse_unknown``).

``read_snapshot`` reads one validated snapshot (errors name the node, the parameter and the
value) and ``read_node_config`` reads one before the node is made (to build what it is given).
"""

from __future__ import annotations

import array
import dataclasses
import difflib
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

from id_learning.config_io import parse_yaml, read_capped, special_kind
from id_learning.errors import ConfigError
from id_learning.nodes.param_schema import (
    STRING_LIST,
    command_line_sources,
    config_from_mapping,
    constraints,
    field_types,
    kind_name,
    params_file_problem,
    params_files,
    value_problem,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance
    from rclpy.node import Node

__all__ = [
    'COMMAND_LINE',
    'check_given_values',
    'declare_parameters',
    'params_file_kind',
    'read_node_config',
    'read_snapshot',
    'refuse_foreign_params_files',
    'refuse_unknown',
]

_T = TypeVar('_T', bound='DataclassInstance')

#: The arguments ``runtime.run_node`` gave rclpy.init (None: ``sys.argv``): where the node's
#: ``-p`` values and params files come from.
COMMAND_LINE: list[str] | None = None


def params_file_kind(args: Sequence[str] | None) -> str | None:
    """The first ``--params-file`` of a command line (None: ``sys.argv``) that is no regular file.

    Checked before ROS starts: a params file must be a regular file. rcl reads each one while
    ``rclpy.init`` parses the command line, then the node reads it again: for its own checks
    (``refuse_foreign_params_files``) and in rcl again through the probe nodes that tell what
    each source gives (``check_given_values``). A pipe (``--params-file <(...)``) gives its
    text once, so the later reads would find it empty; and rcl's ``fopen`` of a FIFO no process
    writes to waits for a writer without a word. A missing file is left to rcl, which names it
    ("Couldn't parse params file").

    Returns:
        That file, what it is and what to do, for an error line; None when there is none.
    """
    for path in params_files(args):
        kind = special_kind(path)
        if kind is not None:
            hint = (
                '; ROS reads a parameter file more than once as a node starts (rcl, then the '
                "node's own checks) and a pipe gives its text only once: write it to a file"
                if kind.startswith('a FIFO')
                else ''
            )
            return f'--params-file {path}: {kind}, not a regular file{hint}'
    return None


def refuse_foreign_params_files(node: Node, args: Sequence[str] | None = None) -> None:
    """Refuse a ``--params-file`` that repeats a key, or has no section for this node.

    rcl takes a key given twice in one mapping (``torque_rise_s: 0.05`` then ``torque_rise_s:
    5.0``) and keeps the later value without a word; it skips a file with no section for the
    node (a misspelt ``recordr:``) without a word too: the node would run on its defaults, a
    recorder recording the default topics to the default folder. Each file is read as the
    package reads its own YAML (``config_io.parse_yaml``), so a YAML fault rcl let pass is named
    too.

    Args:
        args: the command line; None: ``COMMAND_LINE``.

    Raises:
        ConfigError: names the node and the file; for a repeated key, the key and both lines;
            for a file with no section for the node, its sections and the closest one.
    """
    for path in params_files(COMMAND_LINE if args is None else args):
        try:
            # A regular file, never waited on: rcl read it before (``params_file_kind``).
            text = read_capped(path, 'parameter file', regular=True).decode('utf-8')
        except (ConfigError, UnicodeDecodeError):
            continue  # rcl read it before the node started; nothing to add here
        try:
            data = parse_yaml(text, str(path))
        except ConfigError as err:
            raise ConfigError(f'node {node.get_name()}: --params-file {err}') from None
        problem = params_file_problem(path, data, node.get_name(), node.get_namespace())
        if problem:
            raise ConfigError(f'node {node.get_name()}: {problem}')


# -- what the command line gives ------------------------------------------------------------------
def _parsed(node: Node, words: list[str]) -> dict[str, Any]:
    """The parameters one ``-p`` or ``--params-file`` gives ``node``, as rcl parses them.

    A node of the same name and namespace, given only these arguments, lives while they are
    read: rcl's own parser types the values (YAML) and picks the params file's sections and the
    ``node:name:=value`` prefixes that apply to this node.
    """
    from rclpy.node import Node

    probe = Node(
        node.get_name(),
        namespace=node.get_namespace(),
        context=node.context,
        cli_args=['--ros-args', *words],
        use_global_arguments=False,
        start_parameter_services=False,
        enable_rosout=False,
    )
    try:
        return dict(getattr(probe, '_parameter_overrides', {}))
    finally:
        probe.destroy_node()


def _python_value(kind: object, given: Any) -> Any:
    """The value of an rclpy Parameter as the field reads it: ``[]`` (no type) is an empty list."""
    from rclpy.parameter import Parameter

    if given.type_ == Parameter.Type.NOT_SET:
        return () if kind == STRING_LIST else []
    value = given.value
    return tuple(value) if isinstance(value, list | array.array) else value


def _same(kind: object, one: Any, other: Any) -> bool:
    """Whether two rclpy Parameters give a field one value (1 and 1.0 for a float; NaN too)."""

    def key(given: Any) -> tuple[str, str]:
        value = _python_value(kind, given)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        return type(value).__name__, repr(value)

    return key(one) == key(other)


def check_given_values(node: Node, cls: type, args: Sequence[str] | None = None) -> None:
    """Refuse a value the command line gives that the node cannot use; make the last one count.

    Every value of every ``-p`` and ``--params-file`` for the node is checked alone (type and
    schema), also one a later value replaces: a typo is never passed over. Then the node holds
    the last value given for each parameter, as ROS 2 documents: rcl keeps the first of two
    values of different types instead (``-p rate:=2 -p rate:=20.0`` would play at 2), so the
    node puts the last one back in its overrides.

    Args:
        args: the command line; None: ``COMMAND_LINE``.

    Raises:
        ConfigError: names the node, the parameter, the value and where it was given.
    """
    sources = command_line_sources(COMMAND_LINE if args is None else args)
    types = field_types(cls)
    given: dict[str, list[tuple[str, Any]]] = {}
    for label, words in sources:
        for name, parameter in _parsed(node, words).items():
            if name in types:
                given.setdefault(name, []).append((label, parameter))
    held = getattr(node, '_parameter_overrides', {})
    for name, values in given.items():
        kind = types[name]
        for label, parameter in values:
            problem = value_problem(cls, name, _python_value(kind, parameter))
            if problem:
                raise ConfigError(f'node {node.get_name()}: {problem} (given as {label})')
        kept, last = held.get(name), values[-1][1]
        # (One value given and another held: the node's own parameter_overrides replace the
        # command line's, as rclpy does.)
        if len(values) > 1 and kept is not None and not _same(kind, kept, last):
            held[name] = last


# -- declared and read ----------------------------------------------------------------------------
def declare_parameters(node: Node, cls: type, values: object | None = None) -> None:
    """Declare every field of a node config as a parameter with its description and default.

    Args:
        values: a snapshot (a ``cls``) read before the node was made (``read_node_config``): its
            values are declared, in place of the defaults and of the overrides the node was
            given, which that snapshot already holds.

    Raises:
        ConfigError: a params file with no section for the node, a value given that the node
            cannot use, a value of the wrong type, or a parameter the node does not have.
    """
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    if values is None:
        refuse_foreign_params_files(node)
        check_given_values(node, cls)
    types = field_types(cls)
    ros_types = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
        STRING_LIST: ParameterType.PARAMETER_STRING_ARRAY,
    }
    overrides = getattr(node, '_parameter_overrides', {})
    for item in dataclasses.fields(cls):
        kind = types[item.name]
        default = item.default if values is None else getattr(values, item.name)
        if item.name in overrides:
            overrides[item.name] = _declarable(kind, overrides[item.name])
        descriptor = ParameterDescriptor(
            name=item.name,
            type=ros_types[kind],
            description=item.metadata['description'],
            read_only=item.metadata['read_only'],
            # A YAML '1' for a float parameter is an integer: converted to a double (above, and
            # at runtime in _before_set); rclpy types an empty list as bytes. Other types reach
            # the snapshot, which names them.
            dynamic_typing=kind in (float, STRING_LIST),
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


def _declarable(kind: object, given: Any) -> Any:
    """An override as its field is declared; any other as it is.

    An integer for a float becomes a double; ``[]`` (which ROS gives no type) an empty list for
    a list parameter.
    """
    from rclpy.parameter import Parameter

    if kind is float:
        return _as_double(given)
    if kind == STRING_LIST and given.type_ == Parameter.Type.NOT_SET:
        return Parameter(given.name, value=[])
    return given


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


def _as_integer(given: Any) -> Any:
    """A whole, finite double rclpy Parameter as the integer of the same value; any other as is.

    ``ros2 param set /predictor resync_after 3.0`` (or a tuning UI that sends every number as a
    double) means 3; rclpy would refuse it without naming the parameter.
    """
    from rclpy.parameter import Parameter

    value = given.value
    if given.type_ != Parameter.Type.DOUBLE or not math.isfinite(value) or value != int(value):
        return given
    return Parameter(given.name, Parameter.Type.INTEGER, int(value))


def _before_set(node: Node, cls: type, changes: list[Any]) -> list[Any]:
    """Refuse an undeclared parameter at runtime, naming it; an int for a float becomes a double.

    rclpy's own refusal names none (its list of undeclared names comes out empty). An integer
    for a float parameter (``ros2 param set`` sends 1 as one) becomes the double of the same
    value, so that the parameter keeps its type DOUBLE; a whole double for an integer parameter
    becomes that integer (``_as_integer``).

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
    types = field_types(cls)
    convert: dict[object, Callable[[Any], Any]] = {float: _as_double, int: _as_integer}
    return [convert.get(types.get(change.name), _as_is)(change) for change in changes]


def _as_is(given: Any) -> Any:
    return given


def _hinted(unknown: list[str], known: list[str]) -> str:
    """The unknown names, each with the closest known one."""
    hints = []
    for name in unknown:
        close = difflib.get_close_matches(name, sorted(known), n=1)
        hints.append(f'{name} (did you mean {close[0]}?)' if close else name)
    return ', '.join(hints)


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
        ConfigError: a value has the wrong type or is out of range, or has none (``[]`` for a
            parameter that is no list; names the parameter).
    """
    from rclpy.exceptions import ParameterUninitializedException

    values = {}
    for item in dataclasses.fields(cls):
        try:
            values[item.name] = node.get_parameter(item.name).value
        except ParameterUninitializedException:
            kind = kind_name(field_types(cls)[item.name])
            raise ConfigError(
                f'node {node.get_name()}: {item.name}: no value (ROS 2 reads [] as a value of '
                f'no type); give a {kind}'
            ) from None
    return config_from_mapping(cls, values, f'node {node.get_name()}')
