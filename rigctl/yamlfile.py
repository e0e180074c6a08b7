"""YAML files that remember where each value stood, so errors can name ``file:line: field``.

Rig files, take manifests, calibration files, board descriptions and ``grid.yaml`` are all read through
:func:`load_yaml_with_lines`; a validation error is mapped back to the line of the offending field by
:func:`describe_validation_error`.

The loader has limits, so a file received from someone else cannot exhaust the machine (an "alias bomb"
of nested anchors expands to billions of nodes from a few hundred bytes): at most :data:`MAX_FILE_BYTES`
bytes, :data:`MAX_ALIASES` aliases, :data:`MAX_NODES` nodes after aliases are expanded and
:data:`MAX_DEPTH` levels of nesting. A file over a limit is refused with one line naming the file and
the limit.
"""

from __future__ import annotations

import difflib
import re
import sys
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from rigctl.errors import RigFileError, SpecVersionError
from rigctl.regular import read_regular

Loc = tuple[str | int, ...]

MAX_FILE_BYTES = 16 * 1024 * 1024  # a 64x64 array's calibration is about 3 MB
MAX_ALIASES = 1000
MAX_NODES = 250_000  # after expanding aliases; a 64x64 array's calibration has 164,000
MAX_DEPTH = 64


class _Limit(Exception):
    """A limit of the loader was hit (turned into a RigFileError naming the file)."""


class _Loader(yaml.SafeLoader):
    """SafeLoader without YAML 1.1 surprises we do not want in rig files (yes/no as booleans stay), counting
    aliases and nesting as it composes."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self.aliases = 0
        self.depth = 0
        self.nodes = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_ALIASES:
                raise _Limit(f"more than {MAX_ALIASES} aliases (*name)")
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise _Limit(f"nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


def _count(loader: _Loader, depth: int) -> None:
    loader.nodes += 1
    if loader.nodes > MAX_NODES:
        raise _Limit(f"more than {MAX_NODES:,} values once aliases are expanded")
    if depth > MAX_DEPTH:
        raise _Limit(f"nested deeper than {MAX_DEPTH} levels once aliases are expanded")


def _construct(node: yaml.Node, loader: _Loader, path: Loc, lines: dict[Loc, int]) -> Any:
    _count(loader, len(path))
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise RigFileError(
                    f"{{file}}:{key_node.start_mark.line + 1}: a key must be a plain value, not a list or mapping"
                )
            key = _scalar(loader, key_node, path)
            if key in out:
                raise RigFileError(f"{{file}}:{key_node.start_mark.line + 1}: duplicate key {key!r}")
            lines[(*path, key)] = key_node.start_mark.line + 1
            out[key] = _construct(value_node, loader, (*path, key), lines)
            # the key's own line is the most useful place to point at
            lines[(*path, key)] = key_node.start_mark.line + 1
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(item, loader, (*path, i), lines) for i, item in enumerate(node.value)]
    return _scalar(loader, node, path)


def _scalar(loader: _Loader, node: yaml.Node, path: Loc) -> Any:
    """A plain value; one PyYAML cannot turn into its type (a whole number of more digits than Python converts,
    a date with month 13) is one line naming the file, line and field, not Python's words."""
    try:
        return loader.construct_object(node, deep=True)
    except ValueError as exc:
        where = f"{{file}}:{node.start_mark.line + 1}: {dotted(path) + ': ' if path else ''}"
        text = str(node.value)
        digits = sum(c.isdigit() for c in text)
        if node.tag.endswith(":int") and digits > sys.get_int_max_str_digits() > 0:
            raise RigFileError(f"{where}a whole number of {digits:,} digits is too long for any value") from None
        shown = text if len(text) <= 40 else text[:37] + "..."
        raise RigFileError(f"{where}cannot read {shown!r}: {exc}") from None


def load_yaml_with_lines(path: Path, text: str | None = None) -> tuple[Any, dict[Loc, int]]:
    """Parse ``path`` (or ``text`` read from it) and return the data and a map from field path to line."""
    try:
        if text is None:  # a regular file, its size checked on the open descriptor (/dev/zero, a FIFO)
            text = read_regular(path, MAX_FILE_BYTES, RigFileError).decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RigFileError(f"{path}: cannot read: {exc}") from None
    if len(text) > MAX_FILE_BYTES:
        raise RigFileError(f"{path}: text of {len(text):,} characters is over the limit of {MAX_FILE_BYTES:,} bytes")
    lines: dict[Loc, int] = {}
    loader: _Loader | None = None
    try:
        loader = _Loader(text)  # checks every character: a control character is refused here
        node = loader.get_single_node()
        data = None if node is None else _construct(node, loader, (), lines)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        raise RigFileError(f"{where}: not valid YAML: {exc.problem}") from None
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow
        raise RigFileError(
            f"{path}: not valid YAML: character {_char(exc.character)} at character {exc.position} is not allowed"
        ) from None
    except yaml.YAMLError as exc:
        raise RigFileError(f"{path}: not valid YAML: {str(exc).splitlines()[0]}") from None
    except _Limit as exc:
        raise RigFileError(f"{path}: refused: {exc} (limit of the YAML reader)") from None
    except RecursionError:
        raise RigFileError(f"{path}: refused: nested too deeply (limit of the YAML reader)") from None
    except RigFileError as exc:
        raise RigFileError(str(exc).replace("{file}", str(path))) from None
    finally:
        if loader is not None:
            loader.dispose()
    return data, lines


def _char(c: Any) -> str:
    return repr(chr(c)) if isinstance(c, int) else repr(c)


def load_yaml(path: Path) -> Any:
    """The data of a YAML file, read with the same limits (for files whose errors need no line numbers)."""
    return load_yaml_with_lines(path)[0]


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
    if kind in ("int_type", "float_type", "int_from_float") and isinstance(got, bool):
        return f"must be a number, got {str(got).lower()} (a boolean)"
    if kind in ("int_type", "int_from_float"):
        return f"must be a whole number, got {got!r}"
    if kind == "float_type":
        return f"must be a number, got {got!r}{_yaml11_float_hint(got)}"
    if kind == "finite_number":
        return f"must be a finite number, got {got!r}"
    message = str(err["msg"])
    message = message.removeprefix("Value error, ").removeprefix("Assertion failed, ")
    message = message[0].lower() + message[1:] if message else message
    return f"{message}, got {got!r}" if "got" not in message and not isinstance(got, dict | list) else message


# what a YAML 1.2 reader takes for a number in exponent form and YAML 1.1 (PyYAML) reads as text: a mantissa
# without a dot (12e-2) or an exponent without a sign (1.2e5)
_EXPONENT = re.compile(r"([-+]?)(\d*)(?:\.(\d*))?[eE]([-+]?)(\d+)")


def _yaml11_float_hint(got: Any) -> str:
    """For ``12e-2``: why it was read as text, and the spelling that is read as a number (``12.0e-2``)."""
    m = _EXPONENT.fullmatch(got) if isinstance(got, str) else None
    if m is None or not (m[2] or m[3]):
        return ""
    sign, whole, frac, exp_sign, exp = m.groups()
    fixed = f"{sign}{whole or '0'}.{frac or '0'}e{exp_sign or '+'}{exp}"
    return f" (read as text: YAML 1.1 needs a dot and a signed exponent in a number, so write {fixed})"


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """The pydantic models an annotation can hold (through Optional, list, dict and Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    out: list[type[BaseModel]] = []
    if typing.get_origin(annotation) is not None or isinstance(annotation, types.UnionType):
        for arg in typing.get_args(annotation):
            out += _models_in(arg)
    return out


def _known_fields(model: type[BaseModel] | None, parent: Loc) -> list[str]:
    """The field names of the model found at ``parent`` inside ``model`` (empty when it cannot be told)."""
    models = [model] if model is not None else []
    for part in parent:
        if isinstance(part, int):
            continue  # an item of a list: the same models
        models = [
            m
            for model_ in models
            if part in model_.model_fields
            for m in _models_in(model_.model_fields[part].annotation)
        ]
    return sorted({name for m in models for name in m.model_fields})


def refuse_unknown_keys(path: Path, data: Mapping[Any, Any], known: Sequence[str], lines: Mapping[Loc, int]) -> None:
    """For a file read without a model (``grid.yaml``): the first key not in ``known`` refused as a model would
    refuse it, ``path:line: key is not a known field; did you mean ...?``."""
    for key in data:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(known)})"
            raise RigFileError(f"{path}:{line_of(lines, (key,))}: {key} is not a known field{hint}")


def _unknown_key(first: Mapping[str, Any], errors: list[Any], model: type[BaseModel] | None) -> str:
    loc = tuple(first["loc"])
    key, parent = str(loc[-1]), loc[:-1]
    missing = [str(e["loc"][-1]) for e in errors if e["type"] == "missing" and tuple(e["loc"][:-1]) == parent]
    close = difflib.get_close_matches(key, missing, n=1) or difflib.get_close_matches(
        key, _known_fields(model, parent), n=1
    )
    hint = f"; did you mean {close[0]!r}?" if close else " (check its spelling and the reference in the README)"
    return f"is not a known field{hint}"


def describe_validation_error(
    path: Path, exc: ValidationError, lines: Mapping[Loc, int], model: type[BaseModel] | None = None
) -> str:
    """One line for the first error of ``exc``: ``path:line: field message`` (and a count of the rest).

    An unknown key comes first, on its own line, with a "did you mean" hint: a mistyped key otherwise shows
    as the correct key missing, on the section's line. ``model`` (the validated class) widens the hint to
    every field of the section.
    """
    errors = exc.errors()
    unknown = [e for e in errors if e["type"] == "extra_forbidden"]
    first = unknown[0] if unknown else errors[0]
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    field = dotted(loc)
    phrase = _unknown_key(first, errors, model) if unknown else _phrase(first)
    text = f"{path}:{line_of(lines, loc)}: {field + ' ' if field else ''}{phrase}"
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
