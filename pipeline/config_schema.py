"""Typed YAML -> frozen dataclass loading, validated by pydantic, errors as one-line `ConfigError`s.

`read_yaml(path)` parses a config file; `load_dataclass(cls, doc, source=path)` builds `cls` (a stdlib dataclass,
nested dataclasses allowed) from the parsed document. YAML rules: scalars are strict (no "3" -> 3, no true -> 1,
no 3 -> "3"; ints are accepted as floats and become floats; NaN/inf are rejected), mappings build dataclasses,
lists build tuples, unknown keys are rejected. A mistake becomes one `ConfigError` naming the file and the key path,
e.g. `configs/x.yaml: noise.laser_m: must be a finite number, got str 'abc'`. `to_plain` is the way back.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import functools
import re
import types
import typing
from os import PathLike
from pathlib import Path
from typing import Literal, TypeVar

import pydantic
import yaml
from annotated_types import Ge, Gt
from pydantic_core import SchemaValidator, core_schema

from pipeline.errors import ConfigError

#: a config number that must be >= 0 / > 0 (sigmas, sizes, times), checked by pydantic at load
NonNegative = typing.Annotated[float, Ge(0)]
Positive = typing.Annotated[float, Gt(0)]

T = TypeVar("T")

_CONFIG = pydantic.ConfigDict(strict=True, extra="forbid", allow_inf_nan=False)
#: a dataclass's `__pydantic_config__` for a file of which only some keys are read (others are another tool's)
OTHER_KEYS_IGNORED = pydantic.ConfigDict(strict=True, extra="ignore", allow_inf_nan=False)
_UNKNOWN = ("extra_forbidden", "unexpected_keyword_argument")
_NUMBER = {"int_type": "an integer", "int_parsing": "an integer", "int_from_float": "an integer",
           "float_type": "a finite number", "float_parsing": "a finite number", "finite_number": "a finite number"}
_BOUND = {"greater_than_equal": (">=", "ge", lambda v, b: v >= b), "greater_than": (">", "gt", lambda v, b: v > b),
          "less_than_equal": ("<=", "le", lambda v, b: v <= b), "less_than": ("<", "lt", lambda v, b: v < b)}
_KIND = {"bool_type": "true or false", "bool_parsing": "true or false", "string_type": "a string",
         "tuple_type": "a list", "list_type": "a list", "dict_type": "a mapping",
         "dataclass_type": "a mapping of keys", "dataclass_args_type": "a mapping of keys"}


class _Loader(yaml.SafeLoader):
    """yaml.SafeLoader that also reads exponents as YAML 1.2 writes them (`1e-6`, `2.5e3`): PyYAML's YAML 1.1
    resolver wants a dot and a signed exponent (`1.0e-6`, `2.5e+3`) and reads the others as text, which the schema
    would refuse as not a number. Quoted scalars stay strings."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def read_yaml(path: str | PathLike):
    """The YAML document in `path` (None if empty), or ConfigError naming the file (and the line of a syntax error)."""
    path = Path(path)
    try:
        return yaml.load(path.read_text(), Loader=_Loader)  # a SafeLoader: no arbitrary objects
    except FileNotFoundError:
        raise ConfigError("config file not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read: {exc}", path) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1} column {mark.column + 1}" if mark is not None else ""
        problem = str(getattr(exc, "problem", None) or exc).replace("\n", " ")
        raise ConfigError(f"not valid YAML{at}: {problem}", path) from None


def to_plain(obj) -> dict:
    """A dataclass as nested dicts, lists and scalars (tuples become lists), as `load_dataclass` reads it back."""
    return _plain(dataclasses.asdict(obj))


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def load_dataclass(cls: type[T], doc, *, source: str | PathLike | None = None,
                   style: Literal["path", "quoted"] = "path", integral_floats: bool = False) -> T:
    """`cls` built from `doc` (parsed YAML), or ConfigError naming `source` and the key path.

    style: how a message names the key: "path" = `camera.fx_px: must be ...`, `camera.fx: unknown key (...)`;
        "quoted" = `'camera.fx_px' must be ...`, `unknown key(s) camera.fx (...)`.
    integral_floats: accept a float with no fractional part (3.0) for an int key (it becomes 3).
    ConfigErrors raised by the dataclasses' own checks (`__post_init__`) are re-raised naming `source`."""
    try:
        return _validator(cls, integral_floats).validate_python([doc])[0]
    except pydantic.ValidationError as exc:
        raise ConfigError(format_error(exc, doc, cls, style=style), source) from None
    except ConfigError as exc:
        if source is None or exc.path is not None:
            raise
        raise ConfigError(str(exc), source) from None


@functools.cache
def _validator(cls: type, integral_floats: bool) -> SchemaValidator:
    # TypeAdapter refuses a config for a dataclass (which may carry its own); the stdlib dataclasses inside a list
    # inherit the list's. Strict mode also wants dataclass and tuple instances where YAML gives mappings and lists:
    # those two are relaxed, every scalar stays strict.
    schema = copy.deepcopy(pydantic.TypeAdapter(list[cls], config=_CONFIG).core_schema)
    _relax(schema, integral_floats)
    return SchemaValidator(schema)


def _relax(node, integral_floats: bool) -> None:
    if isinstance(node, list):
        for item in node:
            _relax(item, integral_floats)
    if not isinstance(node, dict):
        return
    for value in node.values():
        _relax(value, integral_floats)
    if node.get("type") in ("dataclass", "tuple"):
        node["strict"] = False
    elif integral_floats and node.get("type") == "int":
        inner = dict(node)
        node.clear()
        node.update(core_schema.no_info_before_validator_function(_integral_float_to_int, inner))


def _integral_float_to_int(value):
    return int(value) if isinstance(value, float) and value.is_integer() else value


def format_error(exc: pydantic.ValidationError, doc, cls: type, *, style: str = "path") -> str:
    """One line for a pydantic ValidationError of `load_dataclass(cls, doc)`: unknown keys first, else the first
    error (the order of the fields), in `style` (see load_dataclass)."""
    errors = [dict(e, loc=e["loc"][1:]) for e in exc.errors(include_url=False)]  # [1:]: the list around doc
    unknown = [e for e in errors if e["type"] in _UNKNOWN]
    if unknown:
        keys = [_key_path(e, doc) for e in unknown]
        keys = [k for k in keys if k[:-1] == keys[0][:-1]]  # one section: the first's
        return _unknown_keys(keys, _field_names(cls, keys[0][:-1]), style)
    err, keys = _deepest(errors, doc)
    if err["loc"][-1:] == ("[key]",):  # a mapping's key, not its value
        return _sentence(keys[:-1], f"has a key that is not a string: {_show(err['input'])}", style)
    if err["type"] in ("value_error", "assertion_error") and "error" in err.get("ctx", {}):
        return f"{_render(keys)}: {err['ctx']['error']}" if keys else str(err["ctx"]["error"])
    return _sentence(keys, _problem(err, errors, style), style)


def _deepest(errors: list[dict], doc) -> tuple[dict, list]:
    """The first error, or where a union's members fail below it (a list of methods with one misspelt), the
    deepest of those: the user's key that is wrong, not the union member that does not fit at all; at one key, a
    union's literal members ("must be one of") before its type members ("must be a list")."""
    keys = _key_path(errors[0], doc)
    best = (errors[0], keys)
    for e in errors[1:]:
        k = _key_path(e, doc)
        deeper = k[:len(keys)] == keys and len(k) > len(best[1])
        if deeper or (k == best[1] and e["type"] == "literal_error" != best[0]["type"]):  # "must be one of" a value
            best = (e, k)
    return best


def _key_path(err: dict, doc) -> list[str | int]:
    """The error's location as keys and list indices of `doc` (pydantic adds the labels of union members)."""
    keys, node = [], doc
    for i, part in enumerate(err["loc"]):
        if isinstance(node, dict) and part in node:
            node, part = node[part], str(part)
        elif isinstance(node, (list, tuple)) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        elif i == len(err["loc"]) - 1 and err["type"] == "missing":
            if isinstance(node, (list, tuple)):
                break  # an item missing from a fixed-length list: the list is what is wrong
        else:
            continue  # a union member's label, not the user's key
        keys.append(part)
    return keys


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _render(keys) -> str:
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in keys).lstrip(".")


def _sentence(keys, problem: str, style: str) -> str:
    if style == "quoted":
        return f"'{_render(keys)}' {problem}" if keys else f"the top level {problem}"
    return f"{_render(keys)}: {problem}" if keys else problem


def _problem(err: dict, errors: list[dict], style: str) -> str:
    kind, value = err["type"], err["input"]
    got = f"got {'null' if value is None else type(value).__name__} {_show(value)}"
    if kind in _NUMBER:
        if style == "path" and isinstance(value, str) and any(c.isalpha() for c in value):
            return f"must be a plain number (the unit is in the key's name), got {_show(value)}"
        return f"must be {_NUMBER[kind]}, {got}"
    if kind in _KIND:
        return f"must be {_KIND[kind]}, {got}"
    if kind == "literal_error":  # with the other literal members of a union at the same key
        expected = [x for e in errors if e["type"] == "literal_error" and e["loc"][:-1] == err["loc"][:-1]
                    and e["input"] is value for x in re.findall(r"'([^']*)'", e["ctx"]["expected"])] \
            or re.findall(r"'([^']*)'", err["ctx"]["expected"])
        near = _near(value, expected) if isinstance(value, str) else None
        hint = f" (did you mean {near!r}?)" if near else ""
        return f"must be one of {', '.join(map(repr, expected))}, got {_show(value)}{hint}"
    if kind in _BOUND:
        bound = err["ctx"][_BOUND[kind][1]]
        fixed = -value if isinstance(value, (int, float)) and value < 0 and _BOUND[kind][2](-value, bound) else None
        hint = f" (did you mean {fixed!r}?)" if fixed is not None else ""
        return f"must be {_BOUND[kind][0]} {bound:g}, got {_show(value)}{hint}"
    if kind == "missing":
        if isinstance(value, (list, tuple)):  # a fixed-length list: pydantic names each missing item
            n_missing = sum(e["type"] == "missing" and e["loc"][:-1] == err["loc"][:-1] for e in errors)
            return f"must have {len(value) + n_missing} elements, got {len(value)}"
        return "is required"
    if kind in ("too_long", "too_short"):
        ctx = err.get("ctx", {})
        if kind == "too_short":
            return f"must have at least {ctx.get('min_length')} element(s), got {ctx.get('actual_length')}"
        return f"must have {ctx.get('max_length')} elements, got {ctx.get('actual_length')}"
    return f"{err['msg'][0].lower()}{err['msg'][1:]}, {got}"


def _unknown_keys(keys: list, known: list[str] | None, style: str) -> str:
    hint = ""
    if known is not None:
        near = [_near(str(k[-1]), known) for k in keys]
        hint = (f" (did you mean {', '.join(repr(n) for n in near)}?)" if all(near)
                else f" (known: {', '.join(known)})")
    where = ", ".join(_render(k) for k in keys)
    if style == "quoted":
        return f"unknown key(s) {where}{hint}"
    return f"{where}: unknown key{'s' if len(keys) > 1 else ''}{hint}"


def _near(name: str, known: list[str]) -> str | None:
    """The known key `name` most likely means: the one that adds a unit (`fx` -> `fx_px`), else a close spelling."""
    near = [k for k in known if k.startswith(f"{name}_")] or difflib.get_close_matches(name, known, 1, 0.5)
    return near[0] if near else None


def _field_names(cls: type, keys) -> list[str] | None:
    """The keys the dataclass at `keys` (below `cls`) accepts, or None if `keys` does not lead to one."""
    tp = cls
    try:
        for key in [*keys, None]:
            members = typing.get_args(tp) if typing.get_origin(tp) in (typing.Union, types.UnionType) else (tp,)
            if isinstance(key, int):  # an item of a list
                tp = next(typing.get_args(m)[0] for m in members if typing.get_origin(m) is tuple)
                continue
            tp = next(m for m in members if dataclasses.is_dataclass(m))
            if key is not None:
                tp = _keys(tp)[key]
    except (StopIteration, KeyError, IndexError):
        return None
    return list(_keys(tp))


def _keys(cls: type) -> dict[str, type]:
    """The keys a dataclass accepts (a field's pydantic alias, else its name) and their types."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp, alias = hints[f.name], None
        while typing.get_origin(tp) is typing.Annotated:
            alias = next((m.alias for m in tp.__metadata__ if isinstance(m, pydantic.fields.FieldInfo)), alias)
            tp = tp.__origin__
        out[alias or f.name] = tp
    return out
