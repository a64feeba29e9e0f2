"""Text tables as the plain-text importer and the mount tables read them: rows of cells from a file's
lines (whitespace or CSV, a header row, comment lines) and the units their numbers may be given in.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.io.importers import Progress, read_lines

LENGTH_UNITS = {"mm": 0.001, "cm": 0.01, "m": 1.0}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180, "ddeg": math.pi / 1800}  # ddeg: tenths of a degree
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
DELIMITERS = {"auto": None, "comma": ",", "semicolon": ";", "whitespace": ""}
COMMENT_PREFIXES = ("#", "%", "//")


@dataclass(frozen=True)
class Table:
    """A text table: ``rows`` of cells (strings), each with its 1-based ``line_numbers``;
    ``header`` holds the column names when the first row has no number."""

    file: str | None
    header: tuple[str, ...] | None
    rows: list[list[str]]
    line_numbers: list[int]

    @property
    def width(self) -> int:
        if self.header is not None:
            return len(self.header)
        return len(self.rows[0]) if self.rows else 0

    def column_name(self, col: int) -> str:
        """How errors name column ``col`` (0-based): its header name, or "column k" (1-based)."""
        if self.header is not None and self.header[col]:
            return self.header[col]
        return f"column {col + 1}"

    def error(self, message: str, key: str | None = None, line: int | None = None) -> InputError:
        text = f"line {line}: {message}" if line is not None else message
        return InputError(text, file=self.file, key=key)

    def column(self, col: int, *, missing_ok: bool = False) -> np.ndarray:
        """Column ``col`` (0-based) as float64. With ``missing_ok`` an empty cell is NaN and NaN or
        inf are allowed; without, every cell must be a finite number."""
        cells = [row[col] if row[col] or not missing_ok else "nan" for row in self.rows]
        try:
            values = np.array(cells, dtype=np.float64)
        except ValueError:
            values = None
        if values is not None and (missing_ok or np.isfinite(values).all()):
            return values
        for cell, line in zip(cells, self.line_numbers, strict=True):  # find the first bad cell
            try:
                v = float(cell)
            except ValueError:
                got = repr(cell) if cell else "an empty cell"
                raise self.error(f"expected a number, got {got}", self.column_name(col), line) from None
            if not math.isfinite(v):
                raise self.error(f"expected a finite number, got {cell!r}", self.column_name(col), line)
        raise AssertionError("unreachable")  # pragma: no cover


def _is_comment(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith(COMMENT_PREFIXES)


def _split(line: str, delimiter: str) -> list[str]:
    if delimiter == "":
        return line.split()
    return [cell.strip() for cell in next(csv.reader([line], delimiter=delimiter))]


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def parse_table(lines: Iterable[str], file: str | None = None, delimiter: str = "auto") -> Table:
    """Split text lines into a table. Blank lines and lines starting with #, % or // are skipped.

    ``delimiter``: "auto" (comma or semicolon when the first row holds one, else whitespace),
    "comma", "semicolon" or "whitespace". A first row without any number is the header.
    Every row must have as many cells as the first.
    """
    if delimiter not in DELIMITERS:
        raise InputError(f"expected one of {', '.join(DELIMITERS)}, got {delimiter!r}", key="delimiter")
    sep = DELIMITERS[delimiter]
    header: tuple[str, ...] | None = None
    rows: list[list[str]] = []
    numbers: list[int] = []
    width = first_line = None
    for n, line in enumerate(lines, start=1):
        if _is_comment(line):
            continue
        if sep is None:
            sep = "," if "," in line else ";" if ";" in line else ""
        cells = _split(line, sep)
        if width is None:
            width, first_line = len(cells), n
            if not any(_is_number(c) for c in cells):
                header = tuple(cells)
                continue
        if len(cells) != width:
            raise InputError(
                f"line {n}: expected {width} columns (as on line {first_line}), got {len(cells)}", file=file
            )
        rows.append(cells)
        numbers.append(n)
    if not rows:
        raise InputError("no data rows", file=file)
    return Table(file, header, rows, numbers)


def read_table(path: str | Path, delimiter: str = "auto", progress: Progress | None = None) -> Table:
    """``parse_table`` of the (plain or gzipped) file at ``path``."""
    try:
        return parse_table(read_lines(path, progress), file=str(path), delimiter=delimiter)
    except InputError as exc:
        raise exc.in_file(str(path)) from None


def unit_scale(table: dict[str, float], unit: str, key: str) -> float:
    if unit not in table:
        raise InputError(f"expected one of {', '.join(table)}, got {unit!r}", key=key)
    return table[unit]
