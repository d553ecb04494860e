"""Boundary validation helpers: convert, check shape and finiteness, raise ValueError
naming the expected and the actual."""
from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import numpy as np


def check_points(points, name: str = "points", dims: tuple[int, ...] = (2, 3), min_count: int = 1) -> np.ndarray:
    """Return ``points`` as a C-contiguous (n, d) float64 array, d in ``dims``.

    Raises ValueError naming the expected and the actual shape, a non-finite entry, or too few rows.
    """
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an (n, d) array of numbers, d in {dims}; could not convert: {exc}") from None
    if arr.ndim != 2 or arr.shape[1] not in dims:
        raise ValueError(f"{name} must have shape (n, d) with d in {dims}; got shape {arr.shape}")
    if arr.shape[0] < min_count:
        raise ValueError(f"{name} needs at least {min_count} points in {arr.shape[1]}D; got {arr.shape[0]}")
    bad = ~np.isfinite(arr)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise ValueError(f"{name} must be finite; row {row} is {arr[row].tolist()} (remove NaN/inf points first)")
    return np.ascontiguousarray(arr)


def check_vector(v, name: str, size: int) -> np.ndarray:
    """Return ``v`` as a finite float64 vector of length ``size``."""
    try:
        arr = np.asarray(v, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be {size} numbers; could not convert: {exc}") from None
    if arr.shape != (size,):
        raise ValueError(f"{name} must have {size} components; got {arr.size}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite; got {arr.tolist()}")
    return arr


def check_positive(x, name: str) -> float:
    """Return ``x`` as a finite float > 0."""
    try:
        val = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number; got {x!r}") from None
    if not np.isfinite(val) or val <= 0:
        raise ValueError(f"{name} must be a positive finite number; got {val}")
    return val


def check_field(owner, name: str, lo: float | None = None, unit: str = "", strict: bool = False,
                hi: float | None = None, integer: bool = False) -> None:
    """Check the dataclass field ``owner.name``: a finite number (an int if ``integer``; never a
    bool) in ``[lo, hi]`` (``(lo, hi]`` if ``strict``).  Raises ValueError naming the class, the
    field, the expected range with its unit, and the actual value."""
    v = getattr(owner, name)
    kinds = (int,) if integer else (int, float, np.integer, np.floating)
    ok = isinstance(v, kinds) and not isinstance(v, bool) and np.isfinite(v)
    if ok and lo is not None:
        ok = v > lo if strict else v >= lo
    if ok and hi is not None:
        ok = v <= hi
    if not ok:
        what = "an integer" if integer else "a finite number"
        rng = "" if lo is None else f" {'>' if strict else '>='} {lo:g}"
        rng += "" if hi is None else f" and <= {hi:g}"
        unit = f" {unit}" if unit else ""
        raise ValueError(f"{type(owner).__name__}.{name} must be {what}{rng}{unit}; got {v!r}")


def read_toml(path, what: str, flag: str) -> dict:
    """The table of the TOML file ``path`` (tomllib, or tomli on Python 3.10).  ``what`` names the
    file in messages (e.g. "config file"), ``flag`` the option that gave it (e.g. "--config").

    Raises:
        ValueError: one line naming the problem and the fix (no TOML reader, missing or
            unreadable file, invalid TOML).
    """
    try:
        import tomllib  # optional extra: the TOML reader (Python 3.11, or tomli on 3.10)
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli as tomllib  # optional extra: tomli on Python 3.10
        except ModuleNotFoundError:
            raise ValueError(f"{flag} needs Python 3.11 (tomllib) or pip install tomli; "
                             "pass the options as flags instead") from None
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{what} not found: {path}; check the {flag} path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"cannot read {what} {path}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{what} {path} is not valid TOML ({exc}); fix the syntax") from None


def dataclass_from_dict(cls, data: dict):
    """Rebuild a (frozen, possibly nested) dataclass ``cls`` from :func:`dataclasses.asdict`-style
    ``data`` (JSON-ready: lists for tuples, dicts for nested dataclasses, None for absent optional
    ones); fields ``data`` lacks keep their defaults.  The inverse of ``to_dict`` for the
    configurations; ValueError naming an unknown key or the class that refuses a value."""
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__name__} needs a dict of its fields; got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"{cls.__name__} has no field(s) {unknown}; known: {sorted(fields)}")
    hints = typing.get_type_hints(cls)
    kw = {}
    for name, value in data.items():
        kinds = [t for t in (typing.get_args(hints[name]) or (hints[name],)) if dataclasses.is_dataclass(t)]
        if kinds and isinstance(value, dict):
            value = dataclass_from_dict(kinds[0], value)
        elif isinstance(value, list):
            value = tuple(value)
        kw[name] = value
    try:
        return cls(**kw)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{cls.__name__}: {exc}") from None
