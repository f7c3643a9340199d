"""Compiling, said and remembered (adaptive_mj.sim.compile_note; issue 51, item 4): a compile that is not a load
from numba's disk cache is said on stderr with its time, and nothing is said on a load; a law plugin numba cannot
compile is named by file and line with numba's reason, runs on the Python callback, and is not compiled again in
the next run; `adaptive-mj warmup` leaves nothing to compile. Each test runs in fresh processes with an empty
NUMBA_CACHE_DIR of its own."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

FACTORY = '''
from adaptive_mj.sim.native_context import unique_factory


def factory(key):
    @numba.cfunc(types.float64(types.float64), nogil=True, cache=True)
    def callback(x):
        return x + key

    return callback


def lazy_factory(key):
    @numba.njit(cache=True)
    def callback(x):
        return x * key

    return callback


if __name__ == "__main__":
    import sys

    import numba
    from numba import types

    if "--python-default" not in sys.argv:  # as the command line does; from Python the notes are logging's
        from adaptive_mj.notes import show_on_stderr

        show_on_stderr()

    g = {**globals(), "numba": numba, "types": types}
    if "--load-only" in sys.argv:  # as a study's parent: load what the cache holds, compile nothing
        from adaptive_mj.sim.compile_note import NotInCache, loading_only

        out = []
        for make, key, what, kind, arg in ((factory, 7, "a test cfunc", "test cfunc", None),
                                           (lazy_factory, 9, "a test njit", "test njit", 2.0)):
            try:
                with loading_only():
                    fn = unique_factory(make, g, key, what=what, kind=kind)(key)
                    out.append(str(fn.ctypes(1.0) if arg is None else fn(arg)))
            except NotInCache as exc:
                out.append(f"not-in-cache:{exc}")
        print("|".join(out))
        sys.exit(0)
    f = unique_factory(factory, g, 7, what="a test cfunc", kind="test cfunc")(7)
    lazy = unique_factory(lazy_factory, g, 9, what="a test njit", kind="test njit")(9)
    print(f.ctypes(1.0), lazy(2.0))
'''


def _env(cache: Path, **extra) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
               ADAPTIVE_MJ_COMPILE_NOTES="1", **extra)  # the suite turns the notes off (conftest.py): on here
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])])
    return env


def _said(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith(("adaptive-mj: compil", "adaptive-mj: waiting"))]


def test_a_compile_is_said_with_its_time_and_a_cache_load_is_not(tmp_path, monkeypatch):
    script = tmp_path / "factories.py"
    script.write_text(FACTORY)
    runs = [subprocess.run([sys.executable, str(script)], env=_env(tmp_path / "cache"), capture_output=True,
                           text=True, timeout=300, check=True) for _ in range(3)]
    assert [r.stdout.split() for r in runs] == [["8.0", "18.0"]] * 3
    first = _said(runs[0].stderr)
    assert first[0] == "adaptive-mj: compiling a test cfunc: not in numba's cache yet, no figure for it yet"
    assert first[1].startswith("adaptive-mj: compiled a test cfunc in ") and first[1].endswith(
        " s of CPU); kept in numba's cache for the next runs")
    assert first[2].startswith("adaptive-mj: compiling a test njit: not in numba's cache yet")  # at its first call
    assert first[3].startswith("adaptive-mj: compiled a test njit in ") and len(first) == 4
    assert _said(runs[1].stderr) == [] and _said(runs[2].stderr) == []  # loaded from the cache: nothing said
    # from Python, with logging as it comes: the same compiles, nothing said (the "adaptive_mj" logger's notes)
    quiet = subprocess.run([sys.executable, str(script), "--python-default"], env=_env(tmp_path / "cache2"),
                           capture_output=True, text=True, timeout=300, check=True)
    assert quiet.stdout.split() == ["8.0", "18.0"] and quiet.stderr == ""
    assert list((tmp_path / "cache2").rglob("*.nbi"))  # it did compile
    # the time is kept: the next compile of the kind (another variant) is estimated from it
    from adaptive_mj.sim import compile_note

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    kept = json.loads((tmp_path / "cache" / "adaptive_mj" / "compile-times" / "test-cfunc.json").read_text())
    assert kept["seconds"] > 0
    assert compile_note.expectation("another", "test cfunc").startswith("about ")
    # TYPICAL_CPU["1-DOF callback"], the documented figure
    assert compile_note.expectation("another", "1-DOF callback").startswith("typically 3 s of CPU")


def test_loading_only_compiles_nothing_and_loads_what_the_cache_holds(tmp_path):
    """compile_note.loading_only (a study's parent, which leaves compiles to its workers): with an empty cache the
    cfunc and the njit each raise NotInCache naming the variant, and nothing is compiled or said; once a run has
    compiled them, the same block loads both and gives their values."""
    script = tmp_path / "factories.py"
    script.write_text(FACTORY)

    def load_only():
        return subprocess.run([sys.executable, str(script), "--load-only"], env=_env(tmp_path / "cache"),
                              capture_output=True, text=True, timeout=300, check=True)

    cold = load_only()
    assert cold.stdout.strip() == "not-in-cache:a test cfunc|not-in-cache:a test njit", cold.stdout
    assert _said(cold.stderr) == [] and not list((tmp_path / "cache").rglob("*.nbi"))
    subprocess.run([sys.executable, str(script)], env=_env(tmp_path / "cache"), capture_output=True, text=True,
                   timeout=300, check=True)
    warm = load_only()
    assert warm.stdout.strip() == "8.0|18.0" and _said(warm.stderr) == []


BROKEN = '''
from fractions import Fraction

from adaptive_mj.laws.plugin import LawPlugin, Param


def slow(x, ref, theta, phi, f, h, params, rate):
    s = (ref[1] - x[1]) + 5.0 * (ref[0] - x[0])
    half = float(Fraction(1, 2))  # a Python object: plain Python, which numba cannot compile
    for j in range(rate.shape[0]):
        rate[j] = 0.0
    return (theta[0] * ref[2] - f + 2.0 * half * params[0] * s) / h, s


LAW = LawPlugin(law=slow, params=(Param("k", ge=0.0),), adapts=False, doc="not compilable")
'''

RUN_BROKEN = textwrap.dedent('''
    import json, sys, time
    import numpy as np
    from adaptive_mj import run
    from adaptive_mj.notes import show_on_stderr
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load

    show_on_stderr()  # the notes on stderr, as on the command line (from Python they are logging's)

    scn = load(sys.argv[1], overrides=["law={kind='broken', k=200.0, initial_estimates={d=37.0, b=60.0, c=1.0}}"])
    s = build(scn)
    t0 = time.perf_counter()
    fell_back = run(s.plant, s.law, s.reference, duration=0.2, theta_hat0=s.theta_hat0)
    seconds = time.perf_counter() - t0
    s = build(scn)
    python = run(s.plant, s.law, s.reference, duration=0.2, theta_hat0=s.theta_hat0, native=False)
    same = all(np.array_equal(getattr(fell_back, f), getattr(python, f)) for f in ("t", "x", "u", "s", "theta_hat"))
    print(json.dumps({"native": fell_back.meta["native"], "same": same, "seconds": seconds}))
''')


def _broken_plugin(site: Path) -> Path:
    """A law plugin numba cannot compile, installed as a distribution in `site` (its entry point found on
    sys.path): its module's path."""
    module = site / "broken_law.py"
    module.write_text(BROKEN)
    info = site / "broken_law-0.0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-law\nVersion: 0.0.1\n")
    (info / "entry_points.txt").write_text("[adaptive_mj.laws]\nbroken = broken_law:LAW\n")
    return module


def test_a_plugin_numba_cannot_compile_is_named_by_line_and_not_compiled_again(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    module = _broken_plugin(site)
    script = tmp_path / "run_broken.py"
    script.write_text(RUN_BROKEN)
    env = _env(tmp_path / "cache")
    env["PYTHONPATH"] += os.pathsep + str(site)
    scenario = REPO / "examples" / "emod_law" / "heave_emod.toml"
    runs = [subprocess.run([sys.executable, str(script), str(scenario)], env=env, capture_output=True, text=True,
                           timeout=600, check=True) for _ in range(2)]
    out = [json.loads(r.stdout.strip().splitlines()[-1]) for r in runs]
    assert [o["native"] for o in out] == [False, False] and all(o["same"] for o in out)  # the Python path's rows
    notes = [[ln for ln in r.stderr.splitlines() if "could not be compiled" in ln] for r in runs]
    assert [len(n) for n in notes] == [1, 1]
    marker = next((tmp_path / "cache" / "adaptive_mj" / "plugin-not-compiled").glob("*.json"))
    line = next(i for i, text in enumerate(BROKEN.splitlines(), 1) if "Fraction(1, 2)" in text)
    where = f"{module}:{line}: NameError: name 'Fraction' is not defined"
    assert notes[0][0] == ("adaptive-mj: note: law plugin 'broken' could not be compiled for the native callback "
                           f"({where}; numba's full message in {marker}); running it through the Python callback")
    assert notes[1][0] == ("adaptive-mj: note: law plugin 'broken' could not be compiled for the native callback "
                           f"(in an earlier run: {where}; tried again when its source changes, or delete {marker}); "
                           "running it through the Python callback")
    assert _said(runs[0].stderr)[0].startswith("adaptive-mj: compiling the 1-DOF control callback")
    assert _said(runs[1].stderr) == []  # the second run does not try the compiler
    assert json.loads(marker.read_text())["plugin_source_sha256"]
    # an edit to the plugin: compiled again (and said again)
    module.write_text(BROKEN.replace("5.0 *", "6.0 *"))
    again = subprocess.run([sys.executable, str(script), str(scenario)], env=env, capture_output=True, text=True,
                           timeout=600, check=True)
    assert _said(again.stderr)[0].startswith("adaptive-mj: compiling the 1-DOF control callback")
    assert f"({module}:{line}: NameError" in again.stderr


def test_after_warmup_a_run_compiles_nothing(tmp_path):
    """warmup on one of the bench's scenarios (the analytic twin's chunk stepper, a quick compile): it says the
    variant and its time; a run of that scenario afterwards says nothing (everything loads from the cache), and a
    second warmup finds nothing to compile."""
    code = textwrap.dedent('''
        import sys
        from pathlib import Path
        from adaptive_mj.notes import show_on_stderr
        from adaptive_mj.study.warmup import warmup
        show_on_stderr()  # as `adaptive-mj warmup` does
        print(warmup(specs=[(Path(sys.argv[1]), ())], jobs=1, quick=True).text())
    ''')
    scenario = REPO / "scenarios" / "lecture_first_order.toml"
    env = _env(tmp_path / "cache", ADAPTIVE_MJ_LOGS=str(tmp_path / "logs"))
    warm = subprocess.run([sys.executable, "-c", code, str(scenario)], env=env, capture_output=True, text=True,
                          timeout=600, check=True)
    said = _said(warm.stderr)
    assert len(said) == 2 and "compiled" in said[1]
    assert said[0].startswith(
        "adaptive-mj: compiling the twin plant's chunk stepper (a plant form of order 1, theta = ")
    assert "1 variant compiled" in warm.stdout
    run = subprocess.run([sys.executable, "-m", "adaptive_mj", "run", "lecture_first_order", "--set",
                          "simulation.duration=6.0", "-o", str(tmp_path / "x.mcap")], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode in (0, 1), run.stderr
    assert _said(run.stderr) == []
    again = subprocess.run([sys.executable, "-c", code, str(scenario)], env=env, capture_output=True, text=True,
                           timeout=600, check=True)
    assert _said(again.stderr) == [] and "nothing to compile" in again.stdout


def test_warmup_refuses_a_bad_jobs_count_in_one_line():
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "warmup", "--quick", "--jobs", "0"], env=_env(REPO),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip() == "adaptive-mj: error: --jobs must be an integer >= 1, got 0"


def test_numbas_reason_is_its_first_line_that_says_something():
    from adaptive_mj.sim.compile_note import PluginNotCompiled, _reason, fallback_line

    message = ("Failed in nopython mode pipeline (step: nopython frontend)\n\x1b[1mUnknown attribute 'foo' of type "
               "float64\n\nFile \"law.py\", line 3:\n<source elided>\nDuring: typing of get attribute at law.py (3)")
    assert _reason(Exception(message)) == "Unknown attribute 'foo' of type float64"
    assert fallback_line("x", ValueError("bad\nmore")) == ("adaptive-mj: note: law plugin 'x' could not be compiled "
                                                          "for the native callback (ValueError: bad); running it "
                                                          "through the Python callback")
    assert "(law.py:3: Unknown" in fallback_line("x", PluginNotCompiled("law.py:3: Unknown", remembered=False))


DICT_LAW = '''
def law(x, ref, theta, phi, f, h, params, rate):
    s = (ref[1] - x[1]) + 5.0 * (ref[0] - x[0])
    gains = dict(k=params[0], lam=5.0)  # a Python dict of gains: numba cannot type it
    for j in range(rate.shape[0]):
        rate[j] = 0.0
    return (theta[0] * ref[2] - f + gains["k"] * s) / h, s
'''


def test_a_plugin_law_with_a_python_dict_is_named_by_its_file_and_the_dict_s_line(tmp_path, monkeypatch):
    """Issue 53: a plugin whose law keeps its gains in a Python dict got "(TypingError: Failed in nopython mode
    pipeline (step: nopython frontend))", no file, no line. numba's error on it names the file and the dict's line,
    with numba's reason in one line."""
    import importlib

    import numba
    import numpy as np
    import pytest
    from numba.core.errors import NumbaError

    from adaptive_mj.sim.compile_note import PluginNotCompiled, fallback_line, plugin_failed

    (tmp_path / "dict_law.py").write_text(DICT_LAW)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    module = importlib.import_module("dict_law")
    z = np.zeros(3)
    with pytest.raises(NumbaError) as info:
        numba.njit(module.law)(z, z, z, z, 0.0, 1.0, np.ones(1), np.zeros(3))
    failed = plugin_failed(info.value, (module.law,), "dict-law-test")
    line = next(i for i, text in enumerate(DICT_LAW.splitlines(), 1) if "dict(k=" in text)
    assert isinstance(failed, PluginNotCompiled)
    assert failed.where_why.startswith(f"{tmp_path / 'dict_law.py'}:{line}: No implementation of function "
                                       "Function(<class 'dict'>)")
    said = fallback_line("dicts", failed)
    assert "\n" not in said and f"dict_law.py:{line}: " in said and "nopython mode pipeline" not in said
