"""YAML files that remember where each value stood, so errors can name ``file:line: field``.

Rig files, take manifests and calibration files are all read through :func:`load_yaml_with_lines`; a
validation error is mapped back to the line of the offending field by :func:`describe_validation_error`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from rigctl.errors import RigFileError, SpecVersionError

Loc = tuple[str | int, ...]


class _Loader(yaml.SafeLoader):
    """SafeLoader without YAML 1.1 surprises we do not want in rig files (yes/no as booleans stay)."""


def _construct(node: yaml.Node, loader: _Loader, path: Loc, lines: dict[Loc, int]) -> Any:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if key in out:
                raise RigFileError(f"{{file}}:{key_node.start_mark.line + 1}: duplicate key {key!r}")
            lines[(*path, key)] = key_node.start_mark.line + 1
            out[key] = _construct(value_node, loader, (*path, key), lines)
            # the key's own line is the most useful place to point at
            lines[(*path, key)] = key_node.start_mark.line + 1
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(item, loader, (*path, i), lines) for i, item in enumerate(node.value)]
    return loader.construct_object(node, deep=True)


def load_yaml_with_lines(path: Path, text: str | None = None) -> tuple[Any, dict[Loc, int]]:
    """Parse ``path`` (or ``text`` read from it) and return the data and a map from field path to line."""
    try:
        if text is None:
            text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RigFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RigFileError(f"{path}: cannot read: {exc}") from None
    loader = _Loader(text)
    lines: dict[Loc, int] = {}
    try:
        node = loader.get_single_node()
        data = None if node is None else _construct(node, loader, (), lines)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        raise RigFileError(f"{where}: not valid YAML: {exc.problem}") from None
    except RigFileError as exc:
        raise RigFileError(str(exc).replace("{file}", str(path))) from None
    finally:
        loader.dispose()
    return data, lines


def line_of(lines: Mapping[Loc, int], loc: Sequence[str | int]) -> int:
    """The line of ``loc`` or of its nearest ancestor that has one (1 for the document)."""
    loc = tuple(loc)
    while loc:
        if loc in lines:
            return lines[loc]
        loc = loc[:-1]
    return lines.get((), 1)


def dotted(loc: Sequence[str | int]) -> str:
    """``('cameras', 3, 'device')`` -> ``cameras[3].device``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _phrase(err: Mapping[str, Any]) -> str:
    kind = err["type"]
    ctx = err.get("ctx") or {}
    got = err.get("input")
    if kind == "missing":
        return "is required"
    if kind == "extra_forbidden":
        return "is not a known field (check its spelling and the rig file reference in the README)"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}[kind]
        bound = next(iter(ctx.values()))
        if isinstance(bound, float) and bound.is_integer():
            bound = int(bound)
        return f"must be {op} {bound}, got {got!r}"
    if kind == "finite_number":
        return f"must be a finite number, got {got!r}"
    message = str(err["msg"])
    message = message.removeprefix("Value error, ").removeprefix("Assertion failed, ")
    message = message[0].lower() + message[1:] if message else message
    return f"{message}, got {got!r}" if "got" not in message and not isinstance(got, dict | list) else message


def describe_validation_error(path: Path, exc: ValidationError, lines: Mapping[Loc, int]) -> str:
    """One line for the first error of ``exc``: ``path:line: field message`` (and a count of the rest)."""
    errors = exc.errors()
    first = errors[0]
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    field = dotted(loc)
    text = f"{path}:{line_of(lines, loc)}: {field + ' ' if field else ''}{_phrase(first)}"
    if len(errors) > 1:
        text += f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})"
    return text


def check_spec(path: Path, data: Any, lines: Mapping[Loc, int], known: int, what: str) -> None:
    """Refuse a document whose ``spec`` is missing, malformed or newer than ``known``."""
    if not isinstance(data, dict):
        raise RigFileError(f"{path}:1: a {what} must be a mapping with 'spec: {known}' at the top")
    if "spec" not in data:
        raise RigFileError(f"{path}:1: spec is required (this rigctl writes and reads 'spec: {known}')")
    spec = data["spec"]
    if not isinstance(spec, int) or isinstance(spec, bool) or spec < 1:
        raise RigFileError(f"{path}:{line_of(lines, ('spec',))}: spec must be a positive integer, got {spec!r}")
    if spec > known:
        raise SpecVersionError(
            f"{path}:{line_of(lines, ('spec',))}: {what} spec {spec} is newer than this rigctl understands "
            f"(spec {known}); upgrade rigctl (pip install --upgrade rigctl)"
        )
