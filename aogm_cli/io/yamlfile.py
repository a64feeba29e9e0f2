"""Reading YAML input files (worlds, map_server maps, mapping parameters).

Every failure is an InputError naming the file, and for bad YAML the line and column.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from aogm_cli.core.errors import InputError


def read_yaml(path: str | Path) -> tuple[str, Any]:
    """(text, parsed value) of the YAML file at ``path``."""
    file = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such file", file=file) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", file=file) from None
    try:
        return text, yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise InputError(f"not valid YAML{where}: {problem}", file=file) from None
