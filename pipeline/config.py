"""Validated settings: frozen dataclasses built from plain mappings (parsed TOML).

Each stage owns its settings dataclass; fields are declared with :func:`setting`, which records
the unit, the allowed range or choices and a one-line description. :func:`from_mapping` turns a
mapping into the dataclass and raises :class:`~pipeline.errors.SceneError` naming the dotted key,
the value and what is allowed, for the first problem found: an unknown key, a missing required
key, a wrong type, or a value out of range.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Water:
...     depth_m: float = setting(ge=0.0, doc="water depth")
>>> from_mapping(Water, {"depth_m": 3}, "water")
Water(depth_m=3.0)
>>> from_mapping(Water, {"depth_m": -1}, "water")
Traceback (most recent call last):
...
pipeline.errors.SceneError: `water.depth_m` must be >= 0.0; got -1.0.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Mapping
from typing import Any

from pipeline.errors import SceneError

__all__ = ["setting", "from_mapping", "describe"]

_MISSING = dataclasses.MISSING


def setting(
    default: Any = _MISSING,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: tuple[Any, ...] | None = None,
    length: int | None = None,
    doc: str = "",
) -> Any:
    """Declare a settings field with its constraints.

    Parameters
    ----------
    default : optional
        Default value; without it the key is required.
    ge, gt, le, lt : float, optional
        Inclusive/exclusive bounds, applied to a number or to every item of a tuple.
    choices : tuple, optional
        The allowed values.
    length : int, optional
        Required length of a tuple value.
    doc : str
        One-line description shown by ``bathy validate --explain``.
    """
    meta = {"ge": ge, "gt": gt, "le": le, "lt": lt, "choices": choices, "length": length}
    meta["doc"] = doc
    if isinstance(default, (list, dict, set)):
        raise TypeError("mutable defaults are not allowed in settings; use a tuple")
    return dataclasses.field(default=default, metadata=meta)


def _fmt(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value)


def _type_name(tp: Any) -> str:
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if dataclasses.is_dataclass(tp):
        return "a table"
    origin = typing.get_origin(tp)
    if origin is tuple:
        return "an array"
    return str(tp)


def _coerce(tp: Any, value: Any, key: str, default: Any = _MISSING) -> Any:
    """Check ``value`` against the annotation ``tp`` and return the stored form.

    A table given for a field whose default is a settings instance starts from that instance,
    so keys left out keep the parent's default (``bathy keys`` shows the same).
    """
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _coerce(args[0], value, key)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise SceneError(f"`{key}` must be a table; got {_fmt(value)}.")
        base = default if dataclasses.is_dataclass(default) else None
        return from_mapping(tp, value, key, base=base)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise SceneError(f"`{key}` must be an array; got {_fmt(value)}.")
        args = typing.get_args(tp)
        item_tp = args[0] if (len(args) == 2 and args[1] is Ellipsis) else None
        if item_tp is None and len(args) != len(value):
            raise SceneError(f"`{key}` must have {len(args)} items; got {len(value)}: {value}.")
        items = []
        for i, item in enumerate(value):
            items.append(_coerce(item_tp or args[i], item, f"{key}[{i}]"))
        return tuple(items)
    if tp is bool:
        if not isinstance(value, bool):
            raise SceneError(f"`{key}` must be true or false; got {_fmt(value)}.")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"`{key}` must be an integer; got {_fmt(value)}.")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"`{key}` must be a number; got {_fmt(value)}.")
        if not math.isfinite(value):
            raise SceneError(f"`{key}` must be a finite number; got {_fmt(value)}.")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise SceneError(f"`{key}` must be a string; got {_fmt(value)}.")
        return value
    raise TypeError(f"unsupported settings annotation {tp!r} for {key}")


def _check_bounds(meta: Mapping[str, Any], value: Any, key: str) -> None:
    if value is None:
        return
    if meta.get("choices") is not None and value not in meta["choices"]:
        allowed = ", ".join(_fmt(c) for c in meta["choices"])
        raise SceneError(f"`{key}` must be one of {allowed}; got {_fmt(value)}.")
    if meta.get("length") is not None and len(value) != meta["length"]:
        raise SceneError(f"`{key}` must have {meta['length']} items; got {len(value)}.")
    items = value if isinstance(value, tuple) else (value,)
    for item in items:
        if not isinstance(item, (int, float)) or isinstance(item, bool):
            continue
        for name, ok, word in (
            ("ge", lambda v, b: v >= b, ">="),
            ("gt", lambda v, b: v > b, ">"),
            ("le", lambda v, b: v <= b, "<="),
            ("lt", lambda v, b: v < b, "<"),
        ):
            bound = meta.get(name)
            if bound is not None and not ok(item, bound):
                got = _fmt(value if not isinstance(value, tuple) else list(value))
                raise SceneError(f"`{key}` must be {word} {bound}; got {got}.")


def from_mapping(cls: type, data: Mapping[str, Any], path: str, *, base: Any = None) -> Any:
    """Build the settings dataclass ``cls`` from ``data``, validating every key.

    Parameters
    ----------
    cls : type
        A frozen dataclass whose fields were declared with :func:`setting`.
    data : Mapping
        Parsed TOML table.
    path : str
        Dotted key of the table, used in error messages (``""`` at the top level).
    base : cls instance, optional
        Values for the keys ``data`` leaves out (a parent setting's default instance);
        without it the class defaults.

    Returns
    -------
    cls instance

    Raises
    ------
    SceneError
        For an unknown or missing key, a wrong type or a value out of range.
    """
    prefix = f"{path}." if path else ""
    if not isinstance(data, Mapping):
        raise SceneError(f"`{path or 'scene'}` must be a table; got {_fmt(data)}.")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    for key in data:
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f" Did you mean `{prefix}{close[0]}`?" if close else ""
            allowed = ", ".join(sorted(fields))
            raise SceneError(f"Unknown key `{prefix}{key}`.{hint} Allowed keys: {allowed}.")
    kwargs = {}
    for name, fld in fields.items():
        key = f"{prefix}{name}"
        if name not in data:
            if base is not None:
                kwargs[name] = getattr(base, name)
                continue
            if fld.default is _MISSING and fld.default_factory is _MISSING:
                doc = fld.metadata.get("doc", "")
                what = f" ({doc})" if doc else ""
                raise SceneError(
                    f"Missing key `{key}`{what}: {_type_name(hints[name])} is required."
                )
            continue
        value = _coerce(hints[name], data[name], key, fld.default)
        _check_bounds(fld.metadata, value, key)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except SceneError:
        raise
    except (TypeError, ValueError) as exc:
        raise SceneError(f"`{path or 'scene'}`: {exc}") from exc


def describe(cls: type, path: str = "", defaults: Any = None) -> list[str]:
    """List every key of ``cls`` (recursively) with its default, bounds and description.

    Parameters
    ----------
    cls : type
        A settings dataclass.
    path : str
        Dotted key of ``cls``'s table.
    defaults : cls instance, optional
        The instance a scene gets when it leaves the table out (a parent field's default);
        its values are the defaults shown, so they are the ones a run uses.

    Returns
    -------
    list of str
        One line per key, e.g. ``"water.depth_m = 10.0  [>= 0]  water depth"``.
    """
    lines = []
    hints = typing.get_type_hints(cls)
    prefix = f"{path}." if path else ""
    for fld in dataclasses.fields(cls):
        tp = hints[fld.name]
        table, how = _table_of(tp)
        if table is not None:
            # an optional table, or an array of tables: its line says so, then its keys
            doc = fld.metadata.get("doc", "")
            lines.append(f"{prefix}{fld.name} = {_fmt(fld.default)}  [{how}]  {doc}".rstrip())
            name = f"{prefix}{fld.name}" + ("[]" if how.startswith("array") else "")
            lines.extend(describe(table, name))
            continue
        if dataclasses.is_dataclass(tp):
            if defaults is not None:
                sub = getattr(defaults, fld.name)
            else:
                sub = fld.default if dataclasses.is_dataclass(fld.default) else None
            lines.extend(describe(tp, f"{prefix}{fld.name}", sub))
            continue
        meta = fld.metadata
        bounds = [
            f"{w} {meta[k]}"
            for k, w in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"))
            if meta.get(k) is not None
        ]
        if meta.get("choices"):
            bounds.append("one of " + ", ".join(_fmt(c) for c in meta["choices"]))
        if defaults is not None:
            default = _fmt(getattr(defaults, fld.name))
        else:
            default = "required" if fld.default is _MISSING else _fmt(fld.default)
        extra = f"  [{'; '.join(bounds)}]" if bounds else ""
        lines.append(f"{prefix}{fld.name} = {default}{extra}  {meta.get('doc', '')}".rstrip())
    return lines


def _table_of(tp: Any) -> tuple[type | None, str]:
    """The settings dataclass inside ``X | None`` or ``tuple[X, ...]``, and how it is given."""
    origin = typing.get_origin(tp)
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    if origin in (typing.Union, types.UnionType) and len(args) == 1:
        if dataclasses.is_dataclass(args[0]):
            return args[0], "optional table"
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        if dataclasses.is_dataclass(args[0]):
            return args[0], "array of tables"
    return None, ""
