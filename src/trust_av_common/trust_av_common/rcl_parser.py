"""rcl's own params-file parser (``rcl_yaml_param_parser``, ROS 2 Jazzy), bound with ctypes.

A node started with ``--ros-args --params-file F1 --params-file F2`` gets its parameter
overrides from ``rcl_parse_yaml_file`` (``ros2/rcl``, ``rcl/src/rcl/arguments.c:
_rcl_parse_param_file``: every file parsed, in command-line order, into one
``rcl_params_t``). This module calls that same C function on the same bytes, so every rule of
the file format (which YAML rcl refuses, how a scalar is typed, how nested maps become dotted
names, how a value written twice fills its type's slot) is rcl's, not a copy of it. No
compiler is needed: the structures below are ``ctypes`` copies of the installed headers.

Struct layouts (ROS 2 Jazzy, ``rcl_yaml_param_parser`` 9.2.x, ``rcutils`` 6.7.x):

* ``rcl_yaml_param_parser/types.h``: ``rcl_bool_array_t``, ``rcl_int64_array_t``,
  ``rcl_double_array_t``, ``rcl_byte_array_t`` (``values`` pointer, ``size_t size``),
  ``rcl_variant_t`` (nine pointers, one per type), ``rcl_node_params_t``
  (``parameter_names``, ``parameter_values``, ``num_params``, ``capacity_params``),
  ``rcl_params_t`` (``node_names``, ``params``, ``num_nodes``, ``capacity_nodes``,
  ``allocator``);
* ``rcutils/allocator.h``: ``rcutils_allocator_t`` (four function pointers and ``state``);
* ``rcutils/types/string_array.h``: ``rcutils_string_array_t`` (``size``, ``data``,
  ``allocator``);
* ``rcutils/error_handling.h``: ``rcutils_error_string_t`` (``char str[1024]``).

The libraries are found as rclpy's extension finds them: by the dynamic loader's search
(``LD_LIBRARY_PATH``, set by a ROS ``setup.bash`` or by the PyPI wheels' bootstrapper), else
in ``<prefix>/lib`` of ``sys.prefix`` and of every ``AMENT_PREFIX_PATH`` entry, with its
dependencies loaded first from the same folder (and the PyPI wheel's vendored libyaml).
"""

from __future__ import annotations

import ctypes
import functools
import os
import re
import sys
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from trust_av_common.params import ParamsError

__all__ = ['PARSER_LIBRARY', 'RclParseError', 'parse_files', 'parse_value', 'rcl_error_line']

PARSER_LIBRARY = 'librcl_yaml_param_parser.so'
"""The shared library of rcl's params-file parser."""
# What librcl_yaml_param_parser.so needs (readelf -d, Jazzy wheels), in load order.
_DEPENDENCIES = ('librcutils.so', 'librosidl_runtime_c.so', 'librosidl_dynamic_typesupport.so',
                 'librmw.so')
_ERROR_MESSAGE_MAX = 1024  # rcutils/error_handling.h RCUTILS_ERROR_MESSAGE_MAX_LENGTH


class _Allocator(ctypes.Structure):
    """``rcutils/allocator.h: rcutils_allocator_t``."""

    _fields_ = [('allocate', ctypes.c_void_p), ('deallocate', ctypes.c_void_p),
                ('reallocate', ctypes.c_void_p), ('zero_allocate', ctypes.c_void_p),
                ('state', ctypes.c_void_p)]


def _array(item: Any, name: str) -> type[ctypes.Structure]:
    """``types.h``: ``{item * values; size_t size;}``."""
    return type(name, (ctypes.Structure,), {
        '_fields_': [('values', ctypes.POINTER(item)), ('size', ctypes.c_size_t)]})


_BoolArray = _array(ctypes.c_bool, 'rcl_bool_array_t')
_Int64Array = _array(ctypes.c_int64, 'rcl_int64_array_t')
_DoubleArray = _array(ctypes.c_double, 'rcl_double_array_t')
_ByteArray = _array(ctypes.c_uint8, 'rcl_byte_array_t')


class _StringArray(ctypes.Structure):
    """``rcutils/types/string_array.h: rcutils_string_array_t``."""

    _fields_ = [('size', ctypes.c_size_t), ('data', ctypes.POINTER(ctypes.c_char_p)),
                ('allocator', _Allocator)]


class _Variant(ctypes.Structure):
    """``types.h: rcl_variant_t``: one pointer per type, NULL when not set."""

    _fields_ = [('bool_value', ctypes.POINTER(ctypes.c_bool)),
                ('integer_value', ctypes.POINTER(ctypes.c_int64)),
                ('double_value', ctypes.POINTER(ctypes.c_double)),
                ('string_value', ctypes.c_char_p),
                ('byte_array_value', ctypes.POINTER(_ByteArray)),
                ('bool_array_value', ctypes.POINTER(_BoolArray)),
                ('integer_array_value', ctypes.POINTER(_Int64Array)),
                ('double_array_value', ctypes.POINTER(_DoubleArray)),
                ('string_array_value', ctypes.POINTER(_StringArray))]


class _NodeParams(ctypes.Structure):
    """``types.h: rcl_node_params_t``."""

    _fields_ = [('parameter_names', ctypes.POINTER(ctypes.c_char_p)),
                ('parameter_values', ctypes.POINTER(_Variant)),
                ('num_params', ctypes.c_size_t), ('capacity_params', ctypes.c_size_t)]


class _Params(ctypes.Structure):
    """``types.h: rcl_params_t``."""

    _fields_ = [('node_names', ctypes.POINTER(ctypes.c_char_p)),
                ('params', ctypes.POINTER(_NodeParams)),
                ('num_nodes', ctypes.c_size_t), ('capacity_nodes', ctypes.c_size_t),
                ('allocator', _Allocator)]


class _ErrorString(ctypes.Structure):
    """``rcutils/error_handling.h: rcutils_error_string_t``."""

    _fields_ = [('str', ctypes.c_char * _ERROR_MESSAGE_MAX)]


def _library_dirs() -> list[Path]:
    """Where an installed rcl keeps its libraries: ``<prefix>/lib`` of this environment and
    of every ``AMENT_PREFIX_PATH`` entry (a sourced colcon or apt install)."""
    prefixes = [sys.prefix, *os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)]
    return [Path(prefix) / 'lib' for prefix in prefixes if prefix]


def _vendored_libs() -> list[Path]:
    """The parser wheel's vendored libyaml (auditwheel renames it ``libyaml-0-<hash>.so.*``
    and keeps it in ``site-packages/ros_rcl_yaml_param_parser.libs``). Only this one: other
    wheels' vendored copies (e.g. LTTng's) abort the process when loaded twice."""
    found: list[Path] = []
    for entry in sys.path:
        folder = Path(entry or '.') / 'ros_rcl_yaml_param_parser.libs'
        if entry and folder.is_dir():
            found.extend(sorted(folder.glob('libyaml-0-*.so*')))
    return found


def load_library(dirs: Sequence[Path] | None = None) -> ctypes.CDLL:
    """Load ``librcl_yaml_param_parser.so`` and declare the functions used here.

    Args:
        dirs: folders to search after the dynamic loader's own search (default:
            :func:`_library_dirs`).

    Returns:
        The loaded library.

    Raises:
        ParamsError: the library is not installed or cannot be loaded (one line).
    """
    reasons: list[str] = []
    library: ctypes.CDLL | None = None
    try:
        library = ctypes.CDLL(PARSER_LIBRARY)
    except OSError as err:
        reasons.append(str(err))
        for folder in _library_dirs() if dirs is None else dirs:
            candidate = folder / PARSER_LIBRARY
            if not candidate.is_file():
                continue
            try:
                for vendored in _vendored_libs()[:1]:
                    ctypes.CDLL(str(vendored), mode=ctypes.RTLD_GLOBAL)
                for name in _DEPENDENCIES:
                    if (folder / name).is_file():
                        ctypes.CDLL(str(folder / name), mode=ctypes.RTLD_GLOBAL)
                library = ctypes.CDLL(str(candidate))
                break
            except OSError as err2:
                reasons.append(str(err2))
    if library is None:
        raise ParamsError(f"cannot load rcl's params-file parser {PARSER_LIBRARY} (pip "
                          'ros-rcl-yaml-param-parser, apt ros-jazzy-rcl-yaml-param-parser; not '
                          'found by the loader nor in <prefix>/lib of sys.prefix or '
                          'AMENT_PREFIX_PATH): '
                          f'{reasons[-1].splitlines()[0] if reasons else "not found"}')
    library.rcl_yaml_node_struct_init.argtypes = [_Allocator]
    library.rcl_yaml_node_struct_init.restype = ctypes.POINTER(_Params)
    library.rcl_yaml_node_struct_fini.argtypes = [ctypes.POINTER(_Params)]
    library.rcl_yaml_node_struct_fini.restype = None
    library.rcl_parse_yaml_file.argtypes = [ctypes.c_char_p, ctypes.POINTER(_Params)]
    library.rcl_parse_yaml_file.restype = ctypes.c_bool
    library.rcl_parse_yaml_value.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p,
                                             ctypes.POINTER(_Params)]
    library.rcl_parse_yaml_value.restype = ctypes.c_bool
    # rcutils is loaded as the parser's dependency; its symbols resolve through it.
    library.rcutils_get_default_allocator.argtypes = []
    library.rcutils_get_default_allocator.restype = _Allocator
    library.rcutils_get_error_string.argtypes = []
    library.rcutils_get_error_string.restype = _ErrorString
    library.rcutils_reset_error.argtypes = []
    library.rcutils_reset_error.restype = None
    return library


@functools.cache
def _parser() -> ctypes.CDLL:
    return load_library()


@contextmanager
def _as_file(data: bytes) -> Iterator[str]:
    """A path ``fopen`` reads ``data`` from: an anonymous memory file (Linux ``memfd``), else
    a private temporary file removed at once (nothing is left on disk either way)."""
    if hasattr(os, 'memfd_create') and Path('/proc/self/fd').is_dir():
        fd = os.memfd_create('trust-av-params', os.MFD_CLOEXEC)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            yield f'/proc/self/fd/{fd}'
        finally:
            os.close(fd)
        return
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'params.yaml'
        path.write_bytes(data)
        yield str(path)


def _c_text(raw: bytes | None) -> str:
    return '' if raw is None else raw.decode('utf-8', 'surrogateescape')


def _variant_slots(variant: _Variant) -> list[Any]:
    """Every slot of an ``rcl_variant_t`` in field order, ``None`` where NULL."""
    def array(pointer: Any, convert: Any) -> Any:
        if not pointer:
            return None
        content = pointer.contents
        return [convert(content.values[i]) for i in range(content.size)]

    strings = None
    if variant.string_array_value:
        content = variant.string_array_value.contents
        strings = [_c_text(content.data[i]) for i in range(content.size)]
    return [
        bool(variant.bool_value[0]) if variant.bool_value else None,
        int(variant.integer_value[0]) if variant.integer_value else None,
        float(variant.double_value[0]) if variant.double_value else None,
        _c_text(variant.string_value) if variant.string_value is not None else None,
        (bytes(array(variant.byte_array_value, int))
         if variant.byte_array_value else None),
        array(variant.bool_array_value, bool),
        array(variant.integer_array_value, int),
        array(variant.double_array_value, float),
        strings,
    ]


def variant_value(variant: _Variant) -> Any:
    """The value rclpy makes of an ``rcl_variant_t``.

    rclpy ``rclpy/src/rclpy/node.cpp: _parameter_from_rcl_variant`` (7.1.x)
    tests the slots in the order bool, integer, double, string, byte array, bool array,
    integer array, double array, string array and takes the first one set; ``None`` is
    rclpy's ``PARAMETER_NOT_SET`` (e.g. ``a: []``).
    """
    for slot in _variant_slots(variant):
        if slot is not None:
            return slot
    return None


def _walk(params: _Params) -> dict[str, dict[str, Any]]:
    """Node sections (in the order rcl stores them: first appearance) to their values."""
    sections: dict[str, dict[str, Any]] = {}
    for node in range(params.num_nodes):
        entry = params.params[node]
        sections[_c_text(params.node_names[node])] = {
            _c_text(entry.parameter_names[index]): variant_value(entry.parameter_values[index])
            for index in range(entry.num_params)}
    return sections


_LOCATION = re.compile(r',\s*at\s+\S+:\d+\s*$')
_LINE = re.compile(r'\s*(?:at line(?:_num)?|near line|Error at line)\s+(\d+)\s*')
_VALUE_TEXT = re.compile(r'((?:Error parsing|Unknown data type of) value) .* (at line)', re.DOTALL)


def rcl_error_line(message: str) -> tuple[int | None, str]:
    """rcl's error text as ``(line, one line without the C source location)``.

    rcl's messages end with ``at line N`` or ``at line_num N`` (``parse.c``) and rcutils
    appends ``, at <file.c>:<line>``; two messages quote the value (``Error parsing value %s``),
    which is replaced by ``(...)`` so that no file content is echoed.
    """
    text = _LOCATION.sub('', message.strip()).strip()
    text = _VALUE_TEXT.sub(r'\1 (...) \2', text)
    match = _LINE.search(text)
    line = int(match.group(1)) if match else None
    if match:
        text = (text[:match.start()] + text[match.end():]).strip()
        text = text.rstrip('.').replace('. Value type', ': value type')
    return line, ' '.join(text.split())


class RclParseError(ParamsError):
    """rcl refused a params file: :attr:`where`, :attr:`line` (None: rcl named none),
    :attr:`reason` (rcl's text, one line) and :attr:`stored`, the node sections rcl had
    stored when it stopped."""

    def __init__(self, message: str, where: str, line: int | None, reason: str,
                 stored: set[str]) -> None:
        super().__init__(message)
        self.where = where
        self.line = line
        self.reason = reason
        self.stored = stored


def parse_files(files: Sequence[tuple[bytes, str]]) -> dict[str, dict[str, Any]]:
    """Parse params files into one structure with rcl, as ``--params-file`` once per file.

    Args:
        files: ``(content, name)`` per file, in command-line order; the name is for
            messages only (the content is what rcl reads).

    Returns:
        Section name as rcl stores it (``/**``, ``planner``, ``/car1/planner``) to
        ``{parameter: value}`` as rclpy reads it (:func:`variant_value`), sections in order of
        first appearance over all files.

    Raises:
        ParamsError: rcl refuses a file: ``<name>: line N: <rcl's reason>`` (no line when rcl
            names none), or the library cannot be loaded.
    """
    library = _parser()
    params = library.rcl_yaml_node_struct_init(library.rcutils_get_default_allocator())
    if not params:
        raise ParamsError('rcl_yaml_node_struct_init failed (out of memory)')
    try:
        for data, where in files:
            library.rcutils_reset_error()
            with _as_file(data) as path:
                accepted = library.rcl_parse_yaml_file(path.encode(), params)
            if not accepted:
                reason = library.rcutils_get_error_string().str.decode('utf-8', 'replace')
                library.rcutils_reset_error()
                line, text = rcl_error_line(reason)
                at = f'line {line}: ' if line is not None else ''
                stored = {_c_text(params.contents.node_names[node])
                          for node in range(params.contents.num_nodes)}
                raise RclParseError(f'{where}: {at}{text} (rcl_parse_yaml_file)', where, line,
                                 text, stored)
        return _walk(params.contents)
    finally:
        library.rcl_yaml_node_struct_fini(params)


def parse_value(name: str, text: str) -> Any:
    """The value rcl makes of ``-p name:=text`` (``rcl/src/rcl/arguments.c:
    _rcl_parse_param_rule`` hands ``text`` to ``rcl_parse_yaml_value``), as rclpy reads it.

    Raises:
        ParamsError: rcl refuses the value (one line), or the library cannot be loaded.
    """
    library = _parser()
    params = library.rcl_yaml_node_struct_init(library.rcutils_get_default_allocator())
    if not params:
        raise ParamsError('rcl_yaml_node_struct_init failed (out of memory)')
    try:
        library.rcutils_reset_error()
        if not library.rcl_parse_yaml_value(b'/**', name.encode(), text.encode(), params):
            reason = library.rcutils_get_error_string().str.decode('utf-8', 'replace')
            library.rcutils_reset_error()
            raise ParamsError(f'-p {name}: {rcl_error_line(reason)[1]} (rcl_parse_yaml_value)')
        return _walk(params.contents)['/**'][name]
    finally:
        library.rcl_yaml_node_struct_fini(params)
