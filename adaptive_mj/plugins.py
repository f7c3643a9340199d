"""What law and plant plugins share: finding them among the installed packages' entry
points, and saying where each comes from (adaptive_mj.laws.plugin, adaptive_mj.plants.plugin)."""
from __future__ import annotations

import hashlib
import inspect
import sys
from dataclasses import dataclass
from typing import Callable, Generic, TypeVar

P = TypeVar("P")
P_co = TypeVar("P_co", covariant=True)


@dataclass(frozen=True)
class Installed(Generic[P_co]):
    """An installed plugin: its entry-point name, the registered object (a laws.plugin.LawPlugin or
    a plants.plugin.PlantPlugin), and where it comes from (distribution, version, sha256 of the
    source of the module that defines it)."""

    name: str
    plugin: P_co
    distribution: str
    version: str
    source_sha256: str

    def describe(self) -> dict:
        """What a log records of it (and replay --verify compares)."""
        return {"name": self.name, "distribution": self.distribution, "version": self.version,
                "source_sha256": self.source_sha256}


def source_hash(fn: Callable) -> str:
    """sha256 of the source of the module that defines fn (of its name when there is no source)."""
    module = inspect.getmodule(fn)
    try:
        if module is None:  # no module to read (as inspect.getsource(None) would say)
            raise TypeError(f"{fn!r} has no module")
        text = inspect.getsource(module)
    except (OSError, TypeError):
        text = getattr(fn, "__qualname__", repr(fn))
    return hashlib.sha256(text.encode()).hexdigest()


def discover(group: str, expected: type[P], what: str, code: Callable[[P], Callable]) -> dict[str, Installed[P]]:
    """Every object of type `expected` registered under the entry-point group, by name. One that
    cannot be loaded, or has another type, is skipped with a one-line note on stderr, so one bad
    package does not stop the others. code(obj): the function whose module source is hashed."""
    from importlib.metadata import entry_points

    out: dict[str, Installed[P]] = {}
    for ep in entry_points(group=group):
        try:
            obj = ep.load()
        except Exception as exc:  # a user's package: say which and go on
            print(f"adaptive-mj: note: {what} plugin {ep.name!r} ({ep.value}) could not be loaded: "
                  f"{type(exc).__name__}: {exc}", file=sys.stderr)
            continue
        if not isinstance(obj, expected):
            print(f"adaptive-mj: note: {what} plugin {ep.name!r} ({ep.value}) is not an "
                  f"{expected.__module__}.{expected.__name__}; skipped", file=sys.stderr)
            continue
        dist = ep.dist
        out[ep.name] = Installed(ep.name, obj, dist.name if dist else "?", dist.version if dist else "?",
                                 source_hash(code(obj)))
    return out


def scan_built_in(package: str, registry: dict, order: tuple[str, ...]) -> None:
    """Import every module of `package` once (each built-in kind registers itself into `registry` when its
    module is imported: found by its own module, not by a list), then put `registry` in `order` in place (a name
    missing from `order` comes last, in registration order). Used by the plant and law kind registries."""
    import importlib
    import pkgutil

    pkg = importlib.import_module(package)
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        importlib.import_module(f"{package}.{info.name}")
    ordered = sorted(registry.items(), key=lambda kv: order.index(kv[0]) if kv[0] in order else len(order))
    registry.clear()
    registry.update(ordered)

