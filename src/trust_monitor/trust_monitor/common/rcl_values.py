"""rcl's params-file values and names (ROS 2 Jazzy, ``rcl_yaml_param_parser``), mirrored in
pure Python for :mod:`trust_monitor.common.rcl_yaml`: how a YAML scalar is typed
(``parse.c: get_value``: YAML 1.1 booleans, ``strtoll``/``strtod`` numbers, strings), the
per-parameter variant rclpy reads (``node.cpp: _parameter_from_rcl_variant``), and rmw's
node-name and namespace rules (``_validate_name``). The rule list with citations is in the
docstring of :mod:`trust_monitor.common.rcl_yaml`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from trust_monitor.common.params import ParamsError

PARAMS_KEY = 'ros__parameters'
"""``impl/types.h``: the key that opens a node's parameters."""

_YAML_STR_TAG = 'tag:yaml.org,2002:str'
_NODE_LEVEL = 1  # impl/types.h MAP_NODE_NAME_LVL
_PARAMS_LEVEL = 2  # impl/types.h MAP_PARAMS_LVL
_TOPIC_MAX = 255 - 8  # rmw validate_full_topic_name.h RMW_TOPIC_MAX_NAME_LENGTH
_NAMESPACE_MAX = _TOPIC_MAX - 2  # rmw validate_namespace.h RMW_NAMESPACE_MAX_LENGTH
_NODE_NAME_MAX = 255  # rmw validate_node_name.h RMW_NODE_NAME_MAX_NAME_LENGTH
TOPIC_NAME_MAX = _TOPIC_MAX
"""rmw's longest full topic name, characters (``RMW_TOPIC_MAX_NAME_LENGTH``)."""
_INT64_MIN = -(2**63)
_INT64_MAX = 2**63 - 1
_DBL_MIN = 2.2250738585072014e-308

# parse.c get_value: the words rcl reads as booleans (unquoted only).
_TRUE_WORDS = frozenset({'Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE',
                         'on', 'On', 'ON'})
_FALSE_WORDS = frozenset({'N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE',
                          'off', 'Off', 'OFF'})
# parse.c get_value: YAML's special floats, read by strtod after the leading non-letters.
_SPECIAL_FLOATS = frozenset({'.nan', '.NaN', '.NAN', '.inf', '.Inf', '.INF', '+.inf', '+.Inf',
                             '+.INF', '-.inf', '-.Inf', '-.INF'})

_C_SPACE = '[ \\t\\n\\v\\f\\r]*'
# strtoll(value, &end, 0) consuming the whole string (C11 7.22.1.4, base 0).
_STRTOLL = re.compile(_C_SPACE + r'([+-]?)(?:0[xX]([0-9a-fA-F]+)|(0[0-7]*)|([1-9][0-9]*))')
# strtod consuming the whole string (C11 7.22.1.3, glibc).
_STRTOD_DEC = re.compile(_C_SPACE + r'([+-]?)((?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)')
_STRTOD_HEX = re.compile(
    _C_SPACE + r'([+-]?)0[xX]((?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+))'
    r'(?:[pP]([+-]?[0-9]+))?')
_STRTOD_INF = re.compile(_C_SPACE + r'([+-]?)(?:inf|infinity)', re.IGNORECASE)
_STRTOD_NAN = re.compile(_C_SPACE + r'([+-]?)nan(?:\([0-9A-Za-z_]*\))?', re.IGNORECASE)


@dataclass
class RclVariant:
    """One parameter value as rcl stores it (``rcl_variant_t``): one slot per type.

    rcl fills the slot of the value's type and leaves the others; rclpy reads the first
    slot set in the order of the fields below (``_parameter_from_rcl_variant``).
    """

    bool_value: bool | None = None
    integer_value: int | None = None
    double_value: float | None = None
    string_value: str | None = None
    bool_array: list[bool] | None = None
    integer_array: list[int] | None = None
    double_array: list[float] | None = None
    string_array: list[str] | None = None

    def value(self) -> Any:
        """The value rclpy gives the node (``None``: rclpy's ``PARAMETER_NOT_SET``)."""
        for slot in (self.bool_value, self.integer_value, self.double_value,
                     self.string_value, self.bool_array, self.integer_array,
                     self.double_array, self.string_array):
            if slot is not None:
                return list(slot) if isinstance(slot, list) else slot
        return None


@dataclass
class _NodeEntry:
    """``rcl_node_params_t``: parameter names and values in insertion order."""

    names: list[str] = field(default_factory=list)
    values: list[RclVariant] = field(default_factory=list)

    def find(self, name: str) -> int:
        """``parse.c: find_parameter``: index of the first entry so named, else a new one."""
        for index, existing in enumerate(self.names):
            if existing == name:
                return index
        self.names.append(name)
        self.values.append(RclVariant())
        return len(self.names) - 1


class RclParams:
    """``rcl_params_t``: node sections in order of first appearance, shared by all files."""

    def __init__(self) -> None:
        self.nodes: dict[str, _NodeEntry] = {}

    def find_node(self, name: str) -> _NodeEntry:
        """``parse.c: find_node``: the section so named, created at the end if new."""
        if name not in self.nodes:
            self.nodes[name] = _NodeEntry()
        return self.nodes[name]

    def resolved(self) -> dict[str, dict[str, Any]]:
        """Each section's parameters as rclpy reads them (later entries over earlier)."""
        return {node: {name: variant.value()
                       for name, variant in zip(entry.names, entry.values, strict=True)}
                for node, entry in self.nodes.items()}


class ParsedParams(dict):  # type: ignore[type-arg]
    """Result of :func:`parse_params_text`: section name to ``{parameter: value}``.

    It is a plain mapping as the project reads params files, and keeps the text and its
    name so that :func:`params_for_node` can replay several files into one structure, as
    rcl does.
    """

    def __init__(self, sections: Mapping[str, dict[str, Any]], text: str, where: str) -> None:
        super().__init__(sections)
        self.text = text
        self.where = where


def _name(text: str) -> str:
    """A key for an error message: escaped to one line and at most 60 characters."""
    shown = text.encode('unicode_escape').decode('ascii')
    return repr(shown if len(shown) <= 60 else shown[:57] + '...')


def _c_string(text: str) -> str:
    """What C sees of a libyaml scalar: the bytes up to the first NUL."""
    return text.split('\0', 1)[0]


def _strtoll(text: str) -> int | None:
    """``strtoll(text, &end, 0)`` if it reads the whole string without ``ERANGE``."""
    match = _STRTOLL.fullmatch(text)
    if match is None:
        return None
    sign, hex_digits, octal, decimal = match.groups()
    if hex_digits is not None:
        number = int(hex_digits, 16)
    elif octal is not None:
        number = int(octal, 8)
    else:
        number = int(decimal, 10)
    number = -number if sign == '-' else number
    if not _INT64_MIN <= number <= _INT64_MAX:
        return None  # ERANGE
    return number


def _strtod(text: str) -> float | None:
    """``strtod(text, &end)`` (glibc) if it reads the whole string without ``ERANGE``."""
    if _STRTOD_INF.fullmatch(text):
        return -math.inf if text.lstrip(' \t\n\v\f\r').startswith('-') else math.inf
    if _STRTOD_NAN.fullmatch(text):
        return math.nan
    match = _STRTOD_HEX.fullmatch(text)
    if match is not None:
        sign, digits, exponent = match.groups()
        whole, _, fraction = digits.partition('.')
        mantissa = int((whole + fraction) or '0', 16)
        exact = Fraction(mantissa) * Fraction(2) ** (int(exponent or '0') - 4 * len(fraction))
    else:
        match = _STRTOD_DEC.fullmatch(text)
        if match is None:
            return None
        sign, digits = match.groups()
        exact = Fraction(digits)
    try:
        number = float(exact)
    except OverflowError:
        return None  # ERANGE: overflow
    if math.isinf(number):
        return None
    if exact != 0 and abs(number) < _DBL_MIN and Fraction(number) != exact:
        return None  # ERANGE: glibc reports an inexact subnormal or zero result
    return -number if sign == '-' else number


def rcl_scalar_value(value: str, quoted: bool, tag: str | None) -> Any:
    """Type one scalar as ``parse.c: get_value`` does.

    Args:
        value: the scalar's text.
        quoted: single- or double-quoted in the file.
        tag: the scalar's resolved tag, if any.

    Returns:
        A bool, int (64-bit), float or str.
    """
    value = _c_string(value)
    if tag == _YAML_STR_TAG or quoted:
        return value
    if value in _TRUE_WORDS:
        return True
    if value in _FALSE_WORDS:
        return False
    number = _strtoll(value)
    if number is not None:
        return number
    if value in _SPECIAL_FLOATS:
        special = math.nan if 'nan' in value.lower() else math.inf
        return -special if value.startswith('-') else special
    real = _strtod(value)
    if real is not None:
        return real
    return value


def _validate_namespace(namespace: str) -> str | None:
    """rmw ``validate_namespace.c``: the problem with an absolute namespace, or None."""
    if namespace == '/':
        return None
    if not namespace:
        return 'namespace must not be empty'
    if namespace[0] != '/':
        return "namespace must be absolute, it must lead with a '/'"
    if namespace[-1] == '/':
        return "namespace must not end with a '/', unless only a '/'"
    if re.fullmatch(r'[A-Za-z0-9_/]*', namespace) is None:
        return "namespace must not contain characters other than alphanumerics, '_', or '/'"
    for index in range(len(namespace) - 1):
        if namespace[index] == '/':
            if namespace[index + 1] == '/':
                return "namespace must not contain repeated '/'"
            if namespace[index + 1].isdigit():
                return 'namespace must not have a token that starts with a number'
    if len(namespace) > _NAMESPACE_MAX:
        return f'namespace should not exceed {_NAMESPACE_MAX} characters'
    return None


def namespace_problem(namespace: str) -> str | None:
    """Why ``namespace`` is not a valid node namespace by rmw's rules
    (``rmw_validate_namespace``, in rmw's own words), or None if it is."""
    return _validate_namespace(namespace)


def _validate_node_name(node_name: str) -> str | None:
    """rmw ``validate_node_name.c``: the problem with a node name, or None."""
    if not node_name:
        return 'node name must not be empty'
    if re.fullmatch(r'[A-Za-z0-9_]+', node_name) is None:
        return "node name must not contain characters other than alphanumerics or '_'"
    if node_name[0].isdigit():
        return 'node name must not start with a number'
    if len(node_name) > _NODE_NAME_MAX:
        return f'node name length should not exceed {_NODE_NAME_MAX}'
    return None


def _validate_name(name: str) -> str | None:
    """``parse.c: _validate_name``: the problem with a section's node name, or None."""
    if name in ('/**', '/*'):
        return None
    namespace, slash, node_name = name.rpartition('/')
    if slash:
        namespace += '/'  # C: the namespace including the last '/'
        absolute = namespace if namespace.startswith('/') else '/' + namespace
        tokens = absolute[:-1].split('/')[1:] if absolute != '/' else []
        if not tokens:
            problem = _validate_namespace('/')
            if problem:
                return problem
        for token in tokens:
            if token == '':
                return 'contains repeated forward slash'
            if token not in ('**', '*'):
                problem = _validate_namespace('/' + token)
                if problem:
                    return problem
    if node_name not in ('*', '**'):
        return _validate_node_name(node_name)
    return None



def _set_value(variant: RclVariant, value: Any, in_sequence: bool, sequence_type: list[type],
               where: str, line: int, parameter: str) -> None:
    """``parse.c: parse_value`` from ``get_value``'s result onwards."""
    kind = type(value)
    if not in_sequence:
        if kind is bool:
            variant.bool_value = value
        elif kind is int:
            variant.integer_value = value
        elif kind is float:
            variant.double_value = value
        else:
            variant.string_value = value
        return
    slot = {bool: 'bool_array', int: 'integer_array', float: 'double_array',
            str: 'string_array'}[kind]
    if not sequence_type:
        sequence_type.append(kind)
        setattr(variant, slot, [])  # the array of this type starts again
    elif sequence_type[0] is not kind:
        type_word = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[kind]
        raise ParamsError(f'{where}: line {line}: parameter {_name(parameter)}: items of one '
                          f'sequence must have one type ({type_word} after '
                          f'{_TYPE_WORDS[sequence_type[0]]}) as rcl requires')
    getattr(variant, slot).append(value)


_TYPE_WORDS = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
