"""Input tables (ratings and study tables) read as a trace is: streamed, checked where each
value enters, one line naming the file, the line and the column.

- **Files.** A regular file of at most :data:`MAX_TABLE_BYTES` (checked before reading: a
  larger one is refused in one line, never read into memory), lines of at most
  :data:`MAX_LINE_CHARS`; UTF-8 with or without a byte-order mark (Excel's "CSV UTF-8"),
  or UTF-16 with its mark (Excel's "Unicode text", tab-separated). The delimiter is the
  header line's: ``,``, ``;`` (Excel in locales with a decimal comma: ``0,5`` is then read
  as 0.5) or a tab. Rows are yielded one at a time with their line numbers.
- **Ids** (participants, drives): one table may not hold two ids that would share a file
  or a spreadsheet cell's meaning: ids equal after Unicode normalisation (NFKC), case
  folding and the file-name form (:func:`file_safe`: ``lab/P1`` and ``lab_P1``, ``P1`` and
  ``p1``, a composed and a decomposed ``Zoé``); an id starting with ``=``, ``+``, ``-``,
  ``@``, a tab or a carriage return (a spreadsheet runs it as a formula: CSV injection) is
  refused.
- **Rating scales** (:class:`RatingScale`): ratings are read on a declared scale
  (``0-100`` by default; ``0-1``, ``1-7``, any ``LOW-HIGH``) and mapped to 0-100; a rating
  outside it, or a table whose ratings all sit in the bottom tenth of it (ratings on 0-1
  given as 0-100, a 1-7 Likert given as 0-100) is refused.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
import os
import re
import stat
import unicodedata
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from trust_av_common.input_files import bounded_lines, not_regular
from trust_monitor.trust_fit import FitError

__all__ = ['MAX_LINE_CHARS', 'MAX_TABLE_BYTES', 'IdCheck', 'RatingScale', 'cell_number',
           'file_safe', 'table_rows']

MAX_TABLE_BYTES = 64 * 1024 * 1024
"""Largest input table, bytes (64 MiB: about a million rows of a ratings table, 2,000
participants with 500 steps per drive and four drives). A larger file is refused before it
is read."""
MAX_LINE_CHARS = 4096
"""Longest line of an input table (a binary file has no line ends)."""
FORMULA_STARTS = ('=', '+', '-', '@', '\t', '\r')
"""First characters a spreadsheet takes for a formula (OWASP, "CSV injection")."""
FEW = 0.1
"""A table whose largest rating is within this fraction of its declared scale's span above
its low end is on another scale (refused)."""


def file_safe(name: str) -> str:
    """``name`` as part of a file name: letters, digits, ``_ . -`` kept (any script), every
    other character ``_``."""
    return re.sub(r'[^\w.-]', '_', unicodedata.normalize('NFKC', name))


class IdCheck:
    """The ids of one column of one table: each checked as it enters (:func:`file_safe`
    collisions, formula starts).

    Args:
        what: the column, for messages (``participant``).
    """

    def __init__(self, what: str) -> None:
        self.what = what
        self.seen: dict[str, tuple[str, str]] = {}

    def check(self, where: str, value: str) -> str:
        """``value`` (stripped) if it is a new id or one seen before, else a one-line
        :class:`FitError` at ``where`` (``file:line``)."""
        value = value.strip()
        if not value:
            raise FitError(f'{where}: column {self.what} is empty')
        if value.startswith(FORMULA_STARTS):
            raise FitError(f'{where}: column {self.what}: {value[:40]!r} starts with '
                           f'{value[0]!r}, which a spreadsheet runs as a formula; rename it')
        key = file_safe(value).casefold()
        first = self.seen.setdefault(key, (value, where))
        if first[0] != value:
            raise FitError(f'{where}: column {self.what}: {value[:40]!r} and {first[0][:40]!r} '
                           f'({first[1]}) are one id on disk and in a spreadsheet '
                           f'({file_safe(value)!r} ignoring case); rename one')
        return value


@dataclass(frozen=True)
class RatingScale:
    """The scale ratings were given on; :meth:`percent` maps them to 0-100.

    Attributes:
        low: the scale's lowest rating.
        high: its highest.
    """

    low: float
    high: float

    @classmethod
    def parse(cls, text: str, where: str = '--rating-scale') -> RatingScale:
        """``LOW-HIGH`` (``0-100``, ``0-1``, ``1-7``, ``-3-3``).

        Raises:
            FitError: not two finite numbers with LOW < HIGH (named at ``where``).
        """
        match = re.fullmatch(r'\s*(-?[0-9.]+)\s*-\s*(-?[0-9.]+)\s*', text)
        try:
            low, high = (float(match.group(1)), float(match.group(2))) if match else (0, 0)
        except ValueError:
            low = high = 0.0
        if not (match and math.isfinite(low) and math.isfinite(high) and low < high):
            raise FitError(f'{where}: {text[:40]!r} is not a rating scale LOW-HIGH '
                           '(e.g. 0-100, 0-1, 1-7)')
        return cls(low, high)

    def __str__(self) -> str:
        return f'{self.low:g}-{self.high:g}'

    def percent(self, where: str, value: float) -> float:
        """``value`` on 0-100.

        Raises:
            FitError: outside the scale (named at ``where``).
        """
        if not self.low <= value <= self.high:
            raise FitError(f'{where}: {value:g} is outside the declared rating scale {self} '
                           '(--rating-scale, or a rating_scale column)')
        return 100.0 * (value - self.low) / (self.high - self.low)

    def too_narrow(self, largest: float) -> bool:
        """Whether ratings whose largest is ``largest`` cannot be on this scale."""
        return largest - self.low <= FEW * (self.high - self.low)


def _encoding(head: bytes) -> str:
    if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        return 'utf-16'
    return 'utf-8-sig'


def cell_number(text: str, what: str, decimal: str = '.') -> float | None:
    """A table cell as a finite number (``None`` if it is empty); ``decimal`` is the
    row's decimal separator (:func:`table_rows`).

    Raises:
        FitError: ``what``: not a number, or not finite (``nan``, ``inf``).
    """
    text = text.strip()
    if text == '':
        return None
    try:
        value = float(text.replace(',', '.') if decimal == ',' else text)
    except ValueError:
        raise FitError(f'{what}: not a number: {text[:40]!r}') from None
    if not math.isfinite(value):
        raise FitError(f'{what}: not finite: {text[:40]!r}')
    return value


def table_rows(path: Path, columns: tuple[str, ...]
               ) -> Iterator[tuple[int, dict[str, str], str]]:
    """The rows of the table ``path`` one at a time: (line, row, decimal separator).

    Args:
        path: the table.
        columns: the columns it must have (others are kept in each row).

    Raises:
        FitError: not a regular file, larger than :data:`MAX_TABLE_BYTES`, not UTF-8 or
            UTF-16 text, not CSV, empty, a missing or doubled column, a row with more or
            fewer values than the header, or no row after the header.
    """
    kind = not_regular(path)
    if kind is not None:
        raise FitError(f'{path}: not a regular file ({kind}; expected a CSV table)')
    try:
        with Path(path).open('rb') as raw:
            yield from _rows(path, raw, columns)
    except OSError as err:
        raise FitError(f'{path}: cannot read ({err.strerror})') from err


def _rows(path: Path, raw: io.BufferedReader, columns: tuple[str, ...]
          ) -> Iterator[tuple[int, dict[str, str], str]]:
    """:func:`table_rows` of the open file ``raw``."""
    info = os.fstat(raw.fileno())
    if not stat.S_ISREG(info.st_mode):
        raise FitError(f'{path}: not a regular file (expected a CSV table)')
    if info.st_size > MAX_TABLE_BYTES:
        raise FitError(f'{path}: {info.st_size / 2 ** 20:.0f} MiB, larger than the '
                       f'{MAX_TABLE_BYTES // 2 ** 20} MiB an input table may be; split it '
                       '(e.g. by participant)')
    handle = io.TextIOWrapper(raw, encoding=_encoding(raw.peek(4)[:4]), newline='')
    reader = None
    try:
        lines = bounded_lines(handle, path, MAX_LINE_CHARS, FitError, ' (not a CSV table)')
        first = next(lines, None)
        if first is None or not first.strip():
            raise FitError(f'{path}: empty file (expected the header '
                           f'{",".join(columns)})')
        delimiter = max(',;\t', key=first.count)
        decimal = ',' if delimiter == ';' else '.'
        reader = csv.reader(lines, delimiter=delimiter, strict=True)
        header = [h.strip() for h in next(csv.reader([first], delimiter=delimiter))]
        doubled = sorted({h for h in header if header.count(h) > 1})
        if doubled:
            raise FitError(f'{path}:1: column {doubled[0]!r} appears twice')
        missing = [c for c in columns if c not in header]
        if missing:
            raise FitError(f'{path}:1: missing column(s) {", ".join(missing)} (need '
                           f'{", ".join(columns)})')
        rows = 0
        for line, values in enumerate(reader, start=2):
            if not values or not any(v.strip() for v in values):
                continue
            if len(values) != len(header):
                raise FitError(f'{path}:{line}: expected {len(header)} values, got '
                               f'{len(values)}')
            rows += 1
            yield line, dict(zip(header, values, strict=True)), decimal
    except UnicodeError as err:
        raise FitError(f'{path}: not UTF-8 or UTF-16 text (export it as "CSV UTF-8")') \
            from err
    except csv.Error as err:
        line = reader.line_num + 1 if reader is not None else 1
        raise FitError(f'{path}:{line}: not CSV text ({err})') from err
    if not rows:
        raise FitError(f'{path}: no rows, only the header')
