"""The strict reader of a scenario's TOML tables (`Table`) and the declaration of a kind's keys (`Key`).

Every plant kind and law kind reads its own keys with a Table (adaptive_mj.plants.kinds, adaptive_mj.laws.kinds);
the scenario loader (adaptive_mj.setup.scenario) hands each its table. Validation is strict: unknown keys,
wrong types, non-finite numbers and out-of-range values are a ScenarioError whose one line names the file, the
key, what was expected and what came, e.g. ``scenarios/x.toml: law.gamma must be > 0, got -1``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

from adaptive_mj.errors import ScenarioError

class _Missing:
    """The type of _MISSING: "no default given" (the key is required), told apart from a default of None."""


_MISSING = _Missing()


class Table:
    """Typed, range-checked access to one TOML table; reports unknown keys.

    Each reader returns the checked value, or its default when the key is absent (the key is required
    when no default is given). The overloads say so to the checker: a reader returns None only when
    its default may be None."""

    def __init__(self, data: dict, prefix: str, where: str):
        self.data, self.prefix, self.where = data, prefix, where
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.prefix}{name}"

    def fail(self, name: str, expected: str, got: Any) -> ScenarioError:
        return ScenarioError(f"{self.where}: {self.key(name)} must be {expected}, got {_show(got)}")

    def get(self, name: str, default: Any = _MISSING) -> Any:
        self.used.add(name)
        if name not in self.data:
            if default is _MISSING:
                import difflib

                close = difflib.get_close_matches(name, [k for k in self.data if isinstance(k, str)], n=1)
                hint = f" (found {self.key(close[0])!r}: a misspelling?)" if close else ""
                raise ScenarioError(f"{self.where}: {self.key(name)} is required but missing{hint}")
            return default
        return self.data[name]

    @overload
    def number(self, name: str, default: None, *, gt: float | None = None, ge: float | None = None,
               allow_inf: bool = False) -> float | None: ...
    @overload
    def number(self, name: str, default: float | _Missing = ..., *, gt: float | None = None,
               ge: float | None = None, allow_inf: bool = False) -> float: ...
    def number(self, name: str, default: float | _Missing | None = _MISSING, *, gt: float | None = None,
               ge: float | None = None, allow_inf: bool = False) -> float | None:
        if name not in self.data:
            return self.get(name, default)
        v = self.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(name, "a number", v)
        v = float(v)
        if math.isnan(v) or (math.isinf(v) and not allow_inf):
            raise self.fail(name, "a finite number", v)
        if gt is not None and not v > gt:
            raise self.fail(name, f"> {gt}", v)
        if ge is not None and not v >= ge:
            raise self.fail(name, f">= {ge}", v)
        return v

    @overload
    def integer(self, name: str, default: None, *, ge: int | None = None) -> int | None: ...
    @overload
    def integer(self, name: str, default: int | _Missing = ..., *, ge: int | None = None) -> int: ...
    def integer(self, name: str, default: int | _Missing | None = _MISSING, *, ge: int | None = None) -> int | None:
        if name not in self.data:
            return self.get(name, default)
        v = self.get(name)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(name, "an integer", v)
        if ge is not None and v < ge:
            raise self.fail(name, f"an integer >= {ge}", v)
        return v

    @overload
    def string(self, name: str, default: None, *, choices: Sequence[str] | None = None) -> str | None: ...
    @overload
    def string(self, name: str, default: str | _Missing = ..., *, choices: Sequence[str] | None = None) -> str: ...
    def string(self, name: str, default: str | _Missing | None = _MISSING, *,
               choices: Sequence[str] | None = None) -> str | None:
        if name not in self.data:
            return self.get(name, default)
        v = self.get(name)
        if not isinstance(v, str):
            raise self.fail(name, "a string", v)
        if choices is not None and v not in choices:
            raise self.fail(name, "one of " + ", ".join(repr(c) for c in choices), v)
        return v

    def boolean(self, name: str, default: bool | _Missing = _MISSING) -> bool:
        if name not in self.data:
            return self.get(name, default)
        v = self.get(name)
        if not isinstance(v, bool):
            raise self.fail(name, "true or false", v)
        return v

    @overload
    def table(self, name: str, default: None) -> Table | None: ...
    @overload
    def table(self, name: str, default: dict[str, Any] | _Missing = ...) -> Table: ...
    def table(self, name: str, default: dict[str, Any] | _Missing | None = _MISSING) -> Table | None:
        if name not in self.data:
            v = self.get(name, default)
            return None if v is None else Table(v, self.key(name) + ".", self.where)
        v = self.get(name)
        if not isinstance(v, dict):
            raise self.fail(name, "a table", v)
        return Table(v, self.key(name) + ".", self.where)

    @overload
    def numbers(self, name: str, default: None, *, length: int | None = None) -> tuple[float, ...] | None: ...
    @overload
    def numbers(self, name: str, default: tuple[float, ...] | _Missing = ..., *,
                length: int | None = None) -> tuple[float, ...]: ...
    def numbers(self, name: str, default: tuple[float, ...] | _Missing | None = _MISSING, *,
                length: int | None = None) -> tuple[float, ...] | None:
        if name not in self.data:
            return self.get(name, default)
        v = self.get(name)
        if not isinstance(v, list):
            raise self.fail(name, "an array of numbers", v)
        if length is not None and len(v) != length:
            raise self.fail(name, f"an array of {length} numbers", v)
        out = []
        for i, item in enumerate(v):
            if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                raise self.fail(f"{name}[{i}]", "a finite number", item)
            out.append(float(item))
        return tuple(out)

    def numbers_with_inf(self, name: str, *, length: int) -> tuple[float, ...]:
        """An array of `length` numbers, each finite or ±inf (TOML's inf)."""
        v = self.get(name)
        if not isinstance(v, list) or len(v) != length:
            raise self.fail(name, f"an array of {length} numbers (inf allowed)", v)
        for i, item in enumerate(v):
            if isinstance(item, bool) or not isinstance(item, (int, float)) or math.isnan(item):
                raise self.fail(f"{name}[{i}]", "a number (inf allowed)", item)
        return tuple(float(item) for item in v)

    @overload
    def named_numbers(self, name: str, default: None, *, gt: float | None = None) -> dict[str, float] | None: ...
    @overload
    def named_numbers(self, name: str, default: dict[str, Any] | _Missing = ..., *,
                      gt: float | None = None) -> dict[str, float]: ...
    def named_numbers(self, name: str, default: dict[str, Any] | _Missing | None = _MISSING, *,
                      gt: float | None = None) -> dict[str, float] | None:
        sub = self.table(name, default)
        if sub is None:
            return None
        out = {}
        for key in sub.data:
            out[key] = sub.number(key, gt=gt)
        return out

    def finish(self, allowed_extra: tuple[str, ...] = ()) -> None:
        for name in self.data:
            if name not in self.used and name not in allowed_extra:
                raise ScenarioError(f"{self.where}: unknown key {self.key(name)!r}"
                                    + _suggest(name, self.used))


@overload
def joint_values(t: Table, name: str, *, arrays: Literal[False]) -> float | dict[str, float]: ...
@overload
def joint_values(t: Table, name: str, *, arrays: Literal[True]) -> tuple[float, ...] | dict[str, tuple[float, ...]]: ...
def joint_values(t: Table, name: str, *, arrays: bool) -> (
        float | dict[str, float] | tuple[float, ...] | dict[str, tuple[float, ...]]):
    """A value for every joint (a number, or an array with arrays=True), or a table by joint name."""
    v = t.get(name)
    if isinstance(v, dict):
        sub = t.table(name)
        if arrays:
            return {key: sub.numbers(key) for key in v}
        return {key: sub.number(key) for key in v}
    return t.numbers(name) if arrays else t.number(name)


def _show(v: Any) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"an array {v!r}" if len(repr(v)) < 60 else "an array"
    return f"{type(v).__name__} {v!r}" if not isinstance(v, (int, str)) or isinstance(v, bool) else repr(v)


def _suggest(name: str, known: set[str]) -> str:
    import difflib

    close = difflib.get_close_matches(name, sorted(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


@dataclass(frozen=True)
class Key:
    """A scenario key a kind declares (listed by `list --plants` / `list --laws` and docs/SCENARIOS.md):
    name: under the kind's table (e.g. "lambda" for law.lambda); type: what the value is, in words ("number",
    "string", "table {parameter = number}", ...); unit: its SI unit ('' when none); default: the value when
    absent (None: required, or absent means off; `required` says which); bounds: the range in words
    ("> 0", ">= 0", "one of 'a', 'b'"); doc: a line; when: the condition beyond its kind under which it applies,
    in words ("built from a model"), said when it is refused."""

    name: str
    type: str
    unit: str = ""
    default: Any = None
    bounds: str = ""
    doc: str = ""
    required: bool = False
    when: str = ""

    @property
    def takes_table(self) -> bool:
        """Whether its value may be a TOML table (its type says so)."""
        return "table" in self.type

    def describe(self) -> str:
        """The key as `list --laws` shows it: name [unit] = default, or (required)."""
        unit = f" [{self.unit}]" if self.unit else ""
        if self.required:
            return f"{self.name}{unit} (required)"
        if self.default is None:
            return f"{self.name}{unit}"
        number = isinstance(self.default, (int, float)) and not isinstance(self.default, bool)
        return f"{self.name}{unit} = " + (f"{self.default:g}" if number else repr(self.default))
