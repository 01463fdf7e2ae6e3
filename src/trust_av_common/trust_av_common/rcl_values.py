"""What the project reads from rcl's params files besides rcl's parser
(:mod:`trust_av_common.rcl_parser`): the parsed-file type, message formatting, and
rmw's namespace rules for ``--namespace`` (``rmw_validate_namespace``; rcl's parser applies
the same rules to section names itself).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

__all__ = ['PARAMS_KEY', 'TOPIC_NAME_MAX', 'ParsedParams', 'namespace_problem']

PARAMS_KEY = 'ros__parameters'
"""``rcl_yaml_param_parser/src/impl/types.h``: the key that opens a node's parameters."""

_TOPIC_MAX = 255 - 8  # rmw validate_full_topic_name.h RMW_TOPIC_MAX_NAME_LENGTH
_NAMESPACE_MAX = _TOPIC_MAX - 2  # rmw validate_namespace.h RMW_NAMESPACE_MAX_LENGTH
TOPIC_NAME_MAX = _TOPIC_MAX
"""rmw's longest full topic name, characters (``RMW_TOPIC_MAX_NAME_LENGTH``)."""


class ParsedParams(dict):  # type: ignore[type-arg]
    """One params file as rcl reads it: section name to ``{parameter: value}``.

    It is a plain mapping as the project reads params files, and keeps the text and its
    name so that :func:`~trust_av_common.rcl_yaml.params_for_node` can give several
    files to rcl into one structure, as ``--params-file`` once per file does.
    """

    def __init__(self, sections: Mapping[str, dict[str, Any]], text: str, where: str) -> None:
        super().__init__(sections)
        self.text = text
        self.where = where


def _name(text: str) -> str:
    """A key for an error message: escaped to one line and at most 60 characters."""
    shown = text.encode('unicode_escape').decode('ascii')
    return repr(shown if len(shown) <= 60 else shown[:57] + '...')


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
