"""Compiling, said and remembered: what a run prints while numba compiles a variant it does not find in its disk
cache, and what it keeps of a compile (its time, a law plugin numba could not compile) for the next run.

Said. Every compiled callback or chunk stepper is made by a factory (native_context.unique_factory) whose `numba`
global is `announcing(numba, what, kind, variant)`: numba itself, except that its `cfunc` and `njit` with
``cache=True`` say, on stderr, once, "compiling WHAT (not in numba's cache; about N s: ...)" before a compile and
"compiled WHAT in N s" after it, and record the time. Nothing is printed when the machine code loads from the
cache. Whether a function is in the cache is read before it compiles (a cfunc when it is decorated, a lazily
compiled njit at its first call) from numba's own index of the function (`in_disk_cache`: the key numba's
FunctionCache would look up). Two processes that need the same variant (a bench's workers, `adaptive-mj warmup
--jobs N`, the test suite's) compile it once: the second waits for the first (a file lock per variant) and then
loads it.

Remembered, in `state_dir()` (NUMBA_CACHE_DIR/adaptive_mj when that is set, else the user's cache folder,
~/.cache/adaptive-mj): the seconds each variant's and each kind's last compile took on this machine (the "about
N s" of the next one), and a marker per law plugin variant numba could not compile (`PluginNotCompiled`), keyed
by the variant's cache key: a hash of the plugin's module source, numba's version and this package's compiled
code (native_context.source_key). While it is there, a run takes the Python callback at once with a one-line
note; an edit to the plugin gives another key, and the next run tries the compiler again.
"""
from __future__ import annotations

import contextlib
import hashlib
import inspect
import io
import json
import os
import re
import time
from pathlib import Path
from typing import Any, Callable, Iterator

from adaptive_mj import notes

PREFIX = "adaptive-mj: "

#: [s of CPU] a cold compile of each kind, measured one bundled scenario at a time with an empty cache (numba 0.68.1,
#: 2026-12-07, after numba_util.shared_inline_copies; heave_tracking, ur5e_drift with the consistent projection,
#: quadrotor_lemniscate, mrac_time_delay, lecture_heave; load 3-6; docs/PERFORMANCE.md): the figure said where this
#: machine has none of its own yet
TYPICAL_CPU: dict[str, float] = {"1-DOF callback": 3.0, "arm callback": 15.0, "quadrotor callback": 8.5,
                                 "projection": 2.7, "linear MRAC chunk": 4.2, "twin chunk": 4.3}

#: what this process compiled: (what, seconds), in order (adaptive_mj.study.warmup reports them)
COMPILED: list[tuple[str, float]] = []


class VariantBusy(BaseException):
    """Another process compiles the variant this one needs, and this one was told not to wait (`waiting(False)`:
    adaptive_mj.study.warmup's workers take another run meanwhile). A BaseException, as KeyboardInterrupt is, so
    that no `except Exception` on its way (a plugin's fallback to the Python callback) takes it for a failure."""


class NotInCache(BaseException):
    """A variant this process needs is not in numba's disk cache, and it was told to load only (`loading_only()`:
    a study's parent, which leaves the compiles to its workers, overlapped with other runs). Its text is what the
    variant is; `variant` names it (the same for every run that needs it). A BaseException, as VariantBusy is."""

    def __init__(self, what: str, variant: str = ""):
        super().__init__(what)
        self.variant = (what, variant)


_WAIT = {"wait": True, "load_only": False}


@contextlib.contextmanager
def waiting(wait: bool) -> Iterator[None]:
    """In the block, a compile that another process holds the variant's lock of waits for it (True, the default)
    or raises VariantBusy at once (False)."""
    before = _WAIT["wait"]
    _WAIT["wait"] = wait
    try:
        yield
    finally:
        _WAIT["wait"] = before


@contextlib.contextmanager
def loading_only() -> Iterator[None]:
    """In the block, a variant found in numba's disk cache is loaded as always, and one that would have to compile
    raises NotInCache instead (nothing is compiled)."""
    before = _WAIT["load_only"]
    _WAIT["load_only"] = True
    try:
        yield
    finally:
        _WAIT["load_only"] = before


def state_dir() -> Path:
    """Where compile times and plugin markers are kept: NUMBA_CACHE_DIR/adaptive_mj when NUMBA_CACHE_DIR is set
    (so a fresh numba cache starts with no memory either), else $XDG_CACHE_HOME/adaptive-mj (~/.cache)."""
    numba_dir = os.environ.get("NUMBA_CACHE_DIR")
    if numba_dir:
        return Path(numba_dir) / "adaptive_mj"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "adaptive-mj"


def say(text: str) -> None:
    """One note (INFO) through the "adaptive_mj" logger (adaptive_mj.notes): on the command line one line on
    stderr, written at once (two processes' lines do not interleave); from Python where the application's logging
    sends it, nowhere by default. Nothing when the environment sets ADAPTIVE_MJ_COMPILE_NOTES=0 (the test suite
    does, but for the tests of these notes: its other tests read a run's stderr line by line, and whether a variant
    is cached depends on which test ran first)."""
    if os.environ.get("ADAPTIVE_MJ_COMPILE_NOTES", "1") == "0":
        return
    notes.say(PREFIX + text)


# -- is it in numba's disk cache? ------------------------------------------------------------------------------

def in_disk_cache(pyfunc: Callable, sig=None) -> bool | None:
    """Whether numba's disk cache holds machine code of pyfunc (the Python function a cfunc or njit decorates,
    with its closure) for signature `sig` (a numba Signature; None: any signature, for a lazily compiled njit)
    on this CPU: the index entry numba's FunctionCache looks up when it loads. None where that cannot be read
    (another numba: this reads numba's cache index through its internals, numba.core.caching; the caller then
    times the compile and says so after, where it took long)."""
    try:
        from numba.core.caching import FunctionCache
        from numba.core.registry import cpu_target

        cache = FunctionCache(pyfunc)
        key = cache._index_key(sig, cpu_target.target_context.codegen())
        index = cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 (numba's internals moved: cannot tell, and the compile is timed instead)
        return None
    if sig is None:
        return any(k[1:] == key[1:] for k in index)
    return key in index


def _signature(sig):
    """The Signature numba's CFunc keys its cache by (it normalises the decorator's argument the same way)."""
    from numba.core import sigutils
    from numba.core.typing import signature

    args, return_type = sigutils.normalize_signature(sig)
    return signature(return_type, *args)


# -- how long it took last time ---------------------------------------------------------------------------------

def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-") or "x"


def _times_file(name: str) -> Path:
    return state_dir() / "compile-times" / f"{_slug(name)}.json"


def last_time(name: str) -> tuple[float, float | None] | None:
    """([s] wall, [s] CPU or None) of the last recorded compile of `name` (a variant's tag or a kind) on this
    machine, or None."""
    try:
        kept = json.loads(_times_file(name).read_text())
        cpu = kept.get("cpu_seconds")
        return float(kept["seconds"]), None if cpu is None else float(cpu)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _write(path: Path, text: str) -> None:
    """Write atomically (a reader sees the old file or the new one); nothing where the folder is not writable."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError:
        pass


def record_time(variant: str, kind: str, seconds: float, cpu: float) -> None:
    """Keep a compile's wall and CPU time for the variant and its kind (the next one's estimate)."""
    for name in (variant, kind):
        _write(_times_file(name), json.dumps({"seconds": round(seconds, 2), "cpu_seconds": round(cpu, 2),
                                              "at": time.strftime("%Y-%m-%d")}))


def expectation(variant: str, kind: str) -> str:
    """How long a compile of `variant` (of `kind`) should take, and where the figure comes from."""
    for name, source in ((variant, "its last compile"), (kind, f"the last {kind} compiled")):
        last = last_time(name)
        if last is not None:
            wall, cpu = last
            of_cpu = f" ({cpu:.0f} s of CPU)" if cpu is not None else ""
            return f"about {wall:.0f} s{of_cpu}, as {source} on this machine"
    if kind in TYPICAL_CPU:
        return f"typically {TYPICAL_CPU[kind]:.0f} s of CPU (measured 2026-12-07; longer on a busy machine)"
    return "no figure for it yet"


# -- saying it ---------------------------------------------------------------------------------------------------

@contextlib.contextmanager
def _variant_lock(variant: str, what: str) -> Iterator[None]:
    """Hold the variant's file lock for the block; another process that holds it is waited for (said once)."""
    try:
        import fcntl
    except ImportError:  # no POSIX locks: both compile, numba keeps either result
        yield
        return
    path = state_dir() / "locks" / f"{_slug(variant)}.lock"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        f = open(path, "a")
    except OSError:
        yield
        return
    with f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            if not _WAIT["wait"]:
                raise VariantBusy(what) from None
            say(f"waiting for another process that compiles {what}")
            fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _done(what: str, variant: str, kind: str, seconds: float, cpu: float, how: str) -> None:
    """Say and keep a compile's wall time `seconds` (and its `cpu` seconds: less on a busy machine); how: what
    follows on the line."""
    record_time(variant, kind, seconds, cpu)
    COMPILED.append((what, seconds))
    say(f"compiled {what} in {seconds:.1f} s ({cpu:.1f} s of CPU){how}")


SAID_AFTER_S = 2.0  # [s] a build whose cache state could not be read is said after it, when it took this long


def compile_said(build: Callable[[], Any], pyfunc: Callable, sig, *, what: str, kind: str, variant: str) -> Any:
    """build() (numba.cfunc(sig, cache=True, ...)(pyfunc), or the first call of a lazily compiled njit of pyfunc,
    sig None: it loads the machine code from the disk cache, or compiles it), said on stderr when it compiles (see
    the module docstring), under the variant's lock."""
    sig = None if sig is None else _signature(sig)
    cached = in_disk_cache(pyfunc, sig)
    if cached is not False:
        t0, c0 = time.perf_counter(), time.process_time()
        out = build()
        seconds = time.perf_counter() - t0
        if cached and getattr(out, "cache_hits", 1) == 0:  # listed, yet compiled (a data file gone)
            _done(what, variant, kind, seconds, time.process_time() - c0,
                  ": numba's cache index listed it, but it had to compile again")
        elif cached is None and seconds > SAID_AFTER_S:
            _done(what, variant, kind, seconds, time.process_time() - c0,
                  " (numba's cache could not be read beforehand, so this was not said before)")
        return out
    if _WAIT["load_only"]:
        raise NotInCache(what, variant)
    with _variant_lock(variant, what):
        if in_disk_cache(pyfunc, sig):  # another process compiled it while this one waited
            return build()
        say(f"compiling {what}: not in numba's cache yet, {expectation(variant, kind)}")
        t0, c0 = time.perf_counter(), time.process_time()
        out = build()
        _done(what, variant, kind, time.perf_counter() - t0, time.process_time() - c0,
              "; kept in numba's cache for the next runs")
        return out


class _FirstCallSaid:
    """A lazily compiled njit dispatcher (it compiles, or loads from the cache, at its first call) whose first call
    is compile_said's: under the variant's lock, said when it compiles. Every other attribute is the
    dispatcher's."""

    def __init__(self, dispatcher, pyfunc: Callable, what: str, kind: str, variant: str):
        self.dispatcher, self.pyfunc = dispatcher, pyfunc
        self.what, self.kind, self.variant = what, kind, variant
        self.first = True

    def __call__(self, *args):
        if not self.first:
            return self.dispatcher(*args)
        self.first = False
        try:
            return compile_said(lambda: self.dispatcher(*args), self.pyfunc, None, what=self.what, kind=self.kind,
                                variant=self.variant)
        except (VariantBusy, NotInCache):
            self.first = True  # not compiled: the next call asks again
            raise

    def __getattr__(self, name: str):
        return getattr(self.dispatcher, name)


class _Announcing:
    """numba as a factory sees it (`announcing`): numba's own attributes, with `cfunc` and `njit` saying a compile
    that is not a cache load."""

    def __init__(self, numba, what: str, kind: str, variant: str):
        self._numba, self._what, self._kind, self._variant = numba, what, kind, variant

    def __getattr__(self, name: str):
        return getattr(self._numba, name)

    def cfunc(self, sig, **options):
        make = self._numba.cfunc(sig, **options)
        if not options.get("cache"):
            return make
        return lambda pyfunc: compile_said(lambda: make(pyfunc), pyfunc, sig, what=self._what, kind=self._kind,
                                           variant=self._variant)

    def njit(self, *args, **options):
        make = self._numba.njit(*args, **options)
        if args and callable(args[0]) or not options.get("cache"):  # njit(fn): not a cached factory's
            return make

        def decorate(pyfunc):
            dispatcher = make(pyfunc)
            if in_disk_cache(pyfunc):
                return dispatcher
            return _FirstCallSaid(dispatcher, pyfunc, self._what, self._kind, self._variant)

        return decorate


def announcing(numba, what: str, *, kind: str, variant: str):
    """numba for a compiled factory's globals (native_context.unique_factory): its cfunc and njit with cache=True
    say on stderr what they compile (`what`, e.g. "the 1-DOF control callback (...)") and how long it should take
    (from `variant`'s and `kind`'s last compile here, or TYPICAL_CPU), and say nothing when they load from the cache."""
    return _Announcing(numba, what, kind, variant)


#: how every compile note begins (`say`'s: compiling, compiled, waiting)
NOTE_STARTS = (PREFIX + "compil", PREFIX + "waiting")


def is_note(line: str) -> bool:
    """Whether a line of stderr is a compile note (a cold numba cache's: not part of what a run reports)."""
    return line.startswith(NOTE_STARTS)


class CompileLines(io.TextIOBase):
    """A stderr that lets the compile notes through at once (`say`'s: compiling, compiled, waiting; with
    plugin_notes a law plugin's fallback line too) and drops the rest: for work done ahead of the runs that say the
    rest themselves (a study's prewarm, adaptive-mj warmup)."""

    def __init__(self, out, *, plugin_notes: bool = False):
        self.out, self.pending = out, ""
        self.keep = NOTE_STARTS + ((PREFIX + "note: law plugin",) if plugin_notes else ())

    def write(self, text: str) -> int:
        self.pending += text
        *lines, self.pending = self.pending.split("\n")
        for line in lines:
            if line.startswith(self.keep):
                self.out.write(line + "\n")
                self.out.flush()
        return len(text)


# -- a law plugin numba cannot compile ---------------------------------------------------------------------------

class PluginNotCompiled(Exception):
    """numba could not compile a law plugin into the callback (now, or in an earlier run: `remembered`).
    where_why: "FILE:LINE: numba's reason"."""

    def __init__(self, where_why: str, *, remembered: bool, marker: Path | None = None):
        super().__init__(where_why)
        self.where_why, self.remembered, self.marker = where_why, remembered, marker


def _marker(variant: str) -> Path:
    return state_dir() / "plugin-not-compiled" / f"{_slug(variant)}.json"


def refuse_remembered(variant: str) -> None:
    """Raise PluginNotCompiled(remembered=True) where this plugin variant failed to compile in an earlier run."""
    path = _marker(variant)
    try:
        where_why = json.loads(path.read_text())["where_why"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    raise PluginNotCompiled(where_why, remembered=True, marker=path)


def _reason(exc: BaseException) -> str:
    """numba's reason in one line: the first line of its message that says something (not "Failed in nopython
    mode pipeline", "During: ...", a file position or a source excerpt)."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    for line in text.splitlines():
        line = line.strip()
        if (line and not line.startswith(("Failed in ", "During:", "File ", "<source", "^"))
                and not line.endswith("(step: nopython frontend)")):
            return line[:300]
    return type(exc).__name__


def _where(exc: BaseException, plugin_fns: tuple[Callable, ...]) -> str:
    """FILE:LINE in the plugin where numba stopped (its error's location, or the first position its message gives
    in the plugin's file), else the plugin function's first line."""
    files = {}
    for fn in plugin_fns:
        try:
            files[os.path.realpath(inspect.getsourcefile(fn) or fn.__code__.co_filename)] = fn
        except TypeError:
            files[os.path.realpath(fn.__code__.co_filename)] = fn
    loc = getattr(exc, "loc", None)
    if loc is not None and getattr(loc, "filename", None) and os.path.realpath(loc.filename) in files:
        return f"{loc.filename}:{loc.line}"
    for path, line in re.findall(r'File "([^"]+)", line (\d+)', str(exc)):
        if os.path.realpath(path) in files:
            return f"{path}:{line}"
    first = plugin_fns[0]
    return f"{first.__code__.co_filename}:{first.__code__.co_firstlineno}"


def plugin_failed(exc: BaseException, plugin_fns: tuple[Callable, ...], variant: str) -> PluginNotCompiled:
    """The PluginNotCompiled for numba's error `exc` on a plugin (its functions plugin_fns, the law first), with a
    marker written so that later runs do not compile it again (until its source changes: another variant key)."""
    import numba

    where_why = f"{_where(exc, plugin_fns)}: {_reason(exc)}"
    try:
        source = Path(inspect.getsourcefile(plugin_fns[0]) or "").read_bytes()
    except (OSError, TypeError):
        source = b""
    path = _marker(variant)
    _write(path, json.dumps({"where_why": where_why, "plugin_source_sha256": hashlib.sha256(source).hexdigest(),
                             "numba": numba.__version__, "numba_message": str(exc)}, indent=1))
    return PluginNotCompiled(where_why, remembered=False, marker=path if path.exists() else None)


def fallback_line(name: str, exc: BaseException) -> str:
    """The one line a run prints when law plugin `name` falls back to the Python callback because of `exc`."""
    head = f"{PREFIX}note: law plugin {name!r} could not be compiled for the native callback"
    tail = "running it through the Python callback"
    if isinstance(exc, PluginNotCompiled):
        if exc.remembered:
            return (f"{head} (in an earlier run: {exc.where_why}; tried again when its source changes, or delete "
                    f"{exc.marker}); {tail}")
        full = f"; numba's full message in {exc.marker}" if exc.marker is not None else ""
        return f"{head} ({exc.where_why}{full}); {tail}"
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return f"{head} ({type(exc).__name__}: {first[:200]}); {tail}"


def plugin_compiled(build: Callable[[], Any], plugin_fns: tuple[Callable, ...], key: int):
    """build() (a callback variant's compile, sim.native_mujoco.compiled's) as it is where
    no law plugin is compiled in (plugin_fns empty). With one, numba's error becomes PluginNotCompiled, naming the
    plugin's file and line and numba's reason, and is remembered under the variant's key (its cache key, key: it
    hashes the plugin's source and numba's version), so that a later run raises it at once instead of compiling
    again, until the plugin's source changes."""
    if not plugin_fns:
        return build()
    from adaptive_mj.sim import interrupt

    variant = f"{key:x}"
    refuse_remembered(variant)
    try:
        return build()
    except Exception as exc:  # numba's error on the user's code: said and remembered
        interrupt.reraise_stop(exc)  # a stop signal that came while numba compiled, wrapped by Python
        from numba.core.errors import NumbaError

        if not isinstance(exc, NumbaError):
            raise
        raise plugin_failed(exc, plugin_fns, variant) from exc
