"""
Node parameters: declare them typed and read-only, check them, warn about unknown ones.

Errors are :class:`~sensor_comp.nodes.errors.NodeError` naming the node, parameter and rule.
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Sequence

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..files import check_output, OutputError
from .errors import NodeError

__all__ = [
    'check',
    'check_output_parameter',
    'declare',
    'warn_unknown_parameters',
]

_ARRAY_TYPES = {str: Parameter.Type.STRING_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
                float: Parameter.Type.DOUBLE_ARRAY}


def declare(node: Node, name: str, default, description: str, *, dynamic: bool = False,
            item_type: type = str):
    """
    Declare a read-only parameter and return its value (given, else ``default``).

    Args:
        node: The node.
        name: Parameter name.
        default: Default value; its Python type fixes the parameter's type (``float`` accepts
            integers; a ``list`` is an array of ``item_type``: ``str``, ``int`` or ``float``).
        description: What the parameter does, with unit and allowed values.
        dynamic: Accept a value of any type (the caller checks it).

    Raises:
        NodeError: If the given value has the wrong type.

    """
    numeric = isinstance(default, float) and not dynamic
    descriptor = ParameterDescriptor(description=description, read_only=True,
                                     dynamic_typing=numeric or dynamic)
    try:
        if isinstance(default, list):
            value = node.declare_parameter(name, _ARRAY_TYPES[item_type], descriptor).value
            return list(value or [])
        value = node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException as exc:
        raise NodeError(f'{node.get_fully_qualified_name()}: {exc}') from None
    if numeric:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r} must be a '
                            f'number, got {value!r}')
        value = float(value)
    return value


def check(node: Node, name: str, value, ok: bool, expected: str):
    """Return ``value`` or raise :class:`NodeError` naming the node, parameter and rule."""
    if not ok:
        raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r} must be '
                        f'{expected}, got {value!r}')
    return value


def check_output_parameter(node: Node, name: str, path: str, *, kind: str,
                           inputs: Sequence[str] = ()) -> Path:
    """
    Check an output file parameter with :func:`sensor_comp.files.check_output`; return the path.

    Raises:
        NodeError: Naming the node, the parameter and the reason.

    """
    check(node, name, path, bool(path), 'the name of a file to write')
    try:
        return check_output(path, inputs=inputs, kind=kind, forceable=False)
    except OutputError as exc:
        raise NodeError(f'{node.get_fully_qualified_name()}: parameter {name!r}: '
                        f'{exc}') from None


def warn_unknown_parameters(node: Node) -> None:
    """
    Log a warning, naming the closest declared one, for each parameter the node does not declare.

    Call it once the node has declared all of its parameters.
    """
    # rclpy 7.1 has no public getter for the values given to a node: Node.__init__ merges
    # --ros-args -p, parameter files and ``parameter_overrides`` into this dict, which
    # declare_parameter reads.
    given = getattr(node, '_parameter_overrides', {})
    declared = sorted(node.get_parameters_by_prefix(''))
    for name in sorted(set(given) - set(declared)):
        close = difflib.get_close_matches(name, declared, n=1)
        hint = (f'did you mean {close[0]!r}?' if close
                else f'this node has {", ".join(declared)}')
        node.get_logger().warning(f'unknown parameter {name!r} ({hint}) is ignored')
