"""Users' laws as installed plugins (entry-point group adaptive_mj.laws): the example package
in examples/emod_law is built and installed by pip into a clean virtual environment, then found by name and
run through run, sweep, replay --verify and list --laws, compiled into the native callback
(bit-identical to its Python path), with its keys validated like built-in ones."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from clean_env import make_venv, pip_install, shared_site_packages

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "emod_law"
SCENARIO = EXAMPLE / "heave_emod.toml"
JOINT_EXAMPLE = REPO / "examples" / "robust_sl_law"  # a multi-joint law plugin (JointLawPlugin)

BROKEN = '''
from fractions import Fraction

from adaptive_mj.laws.plugin import LawPlugin, Param


def slow(x, ref, theta, phi, f, h, params, rate):
    half = float(Fraction(1, 2))  # a Python object: plain Python, which numba cannot compile
    s = (ref[1] - x[1]) + 5.0 * (ref[0] - x[0])
    for j in range(rate.shape[0]):
        rate[j] = 0.0
    return (theta[0] * ref[2] - f + 2.0 * half * params[0] * s) / h, s


LAW = LawPlugin(law=slow, params=(Param("k", ge=0.0),), adapts=False, doc="not compilable")
'''


GTAB = '''
import numpy as np

from adaptive_mj.laws.plugin import LawPlugin, Param

G = 2  # params: [lambda, k, gamma_1 .. gamma_n]


def gtab(x, ref, theta, phi, f, h, params, rate):
    """The lecture's order-2 sliding law with a per-parameter gain table."""
    lam, k = params[0], params[1]
    e0, e1 = ref[0] - x[0], ref[1] - x[1]
    s = e1 + lam * e0
    s_r_dot = ref[2] + lam * e1
    acc = theta[0] * s_r_dot - f + k * s
    for j in range(phi.shape[0]):
        acc -= phi[j] * theta[j + 1]
    rate[0] = s_r_dot * s / params[G]
    for j in range(phi.shape[0]):
        rate[j + 1] = -phi[j] * s / params[G + 1 + j]
    return acc / h, s


def lyapunov(s, theta_hat, theta, params, M):
    """V = ½ d s² + ½ Σ γ_i θ̃_i² (d = θ[0], the lecture's V)."""
    n = theta_hat.shape[-1]
    return 0.5 * theta[:, 0] * s**2 + 0.5 * np.sum(params[G:G + n] * (theta_hat - theta) ** 2, axis=-1)


LAW = LawPlugin(law=gtab, params=(Param("lambda", default=5.0, gt=0.0, unit="1/s"),
                                  Param("k", default=200.0, ge=0.0, unit="N s/m"),
                                  Param("gamma", default=0.1, gt=0.0, per_parameter=True)),
                lyapunov=lyapunov, gain="gamma", doc="sliding law, per-parameter gains", orders=(2,))
'''

CART = """
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.plugin import Param
from adaptive_mj.plants.mujoco_plant import MujocoPlant, find_joint_and_actuator
from adaptive_mj.plants.plugin import PlantPlugin


def phi(x):
    return np.array([-x[1]])


def true_theta(model):
    return np.array([model.body_mass[1] + model.dof_armature[0], model.dof_damping[0]])


def make(model, params, where):
    model.dof_damping[0] = params["damping"]
    j, a = find_joint_and_actuator(model, joint=None, actuator=None, joint_type=mujoco.mjtJoint.mjJNT_SLIDE,
                                   where=where)
    return MujocoPlant(model, joint_id=j, actuator_id=a, form=ModelForm(order=2, p_names=("b",), phi=phi),
                       theta_fn=true_theta, where=where)


PLANT = PlantPlugin(model=Path(__file__).with_name("cart.xml"), make=make,
                    params=(Param("damping", default=3.0, ge=0.0, unit="N s/m"),),
                    units={"output": "m", "control": "N", "d": "kg", "b": "N s/m"},
                    doc="a cart on a rail with viscous damping: d y'' + b y' = u")
"""
CART_XML = ("<mujoco><option timestep='0.001' integrator='RK4'/><worldbody><body name='cart'>"
            "<joint name='x' type='slide' axis='1 0 0'/><geom type='box' size='.1 .05 .05' mass='2'/></body>"
            "</worldbody><actuator><motor joint='x' ctrlrange='-50 50' ctrllimited='true'/></actuator></mujoco>")
CART_SCENARIO = """schema_version = 1
description = "a plugin plant under the built-in sliding law"
[plant]
kind = "cart"
damping = 4.0
[simulation]
duration = 3.0
initial_state = "reference"
[reference]
kind = "sum_of_sines"
amplitudes = [0.3, 0.1]
omegas = [1.0, 3.0]
[law]
kind = "sliding_adaptive"
lambda = 10.0
k = 50.0
gamma = { d = 0.05, b = 0.05 }
initial_estimates = { d = 1.0, b = 0.0 }
"""


def _package(folder: Path, module: str, source: str, dist: str, version: str, group: str, entry: str) -> Path:
    """A one-module package in `folder` registering `entry` under the entry-point `group`."""
    (folder / f"{module}.py").write_text(source)
    (folder / "pyproject.toml").write_text(
        '[build-system]\nrequires = ["setuptools>=61"]\nbuild-backend = "setuptools.build_meta"\n'
        f'[project]\nname = "{dist}"\nversion = "{version}"\n'
        f'[project.entry-points."{group}"]\n{entry}\n'
        f'[tool.setuptools]\npy-modules = ["{module}"]\n')
    return folder


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """A clean virtual environment: adaptive-mj installed (editable, from this checkout), the example
    plugin built from its own folder and installed by pip, plus a plant plugin and a law numba
    cannot compile. Third-party dependencies (mujoco, numba, ...) are shared read-only from the
    test environment, without its adaptive-mj or any plugin installed there (tests/clean_env.py),
    so nothing is downloaded and the plugins seen are exactly these."""
    root = tmp_path_factory.mktemp("clean_env")
    python = make_venv(root)
    probe = subprocess.run([str(python), "-c", "import adaptive_mj"], capture_output=True, text=True, cwd=root)
    assert probe.returncode != 0  # clean: adaptive-mj is not there until pip installs it
    broken = _package(tmp_path_factory.mktemp("broken_plugin"), "broken_law", BROKEN, "broken-law", "0.0.1",
                      "adaptive_mj.laws", "broken = \"broken_law:LAW\"")
    cart = _package(tmp_path_factory.mktemp("cart_plant"), "cart_plant", CART, "cart-plant", "0.2.0",
                    "adaptive_mj.plants", "cart = \"cart_plant:PLANT\"")
    gtab = _package(tmp_path_factory.mktemp("gtab_law"), "gtab_law", GTAB, "gtab-law", "0.1.0",
                    "adaptive_mj.laws", "gtab = \"gtab_law:LAW\"")
    pip_install(python, "--no-build-isolation", "-e", str(REPO), str(EXAMPLE), str(JOINT_EXAMPLE), str(broken),
                str(cart), str(gtab))
    purelib = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  check=True, capture_output=True, text=True).stdout.strip())
    (purelib / "cart.xml").write_text(CART_XML)  # beside the module, as a package would ship it
    return {"python": python, "purelib": purelib}


@pytest.fixture(scope="module")
def bare(tmp_path_factory) -> Path:
    """A clean virtual environment with adaptive-mj and no plugin at all, whatever the interpreter
    running the tests has installed (a user who followed docs/ADDING_A_LAW.md has emod there)."""
    python = make_venv(tmp_path_factory.mktemp("bare_env"))
    pip_install(python, "--no-build-isolation", "-e", str(REPO))
    return python


@pytest.fixture(scope="module")
def site(env):
    """The clean environment's site-packages, with the plugins' distributions."""
    return env["purelib"]


def cli(site, *args, cwd=None):
    """adaptive-mj run by the clean environment's interpreter (which finds its plugins itself)."""
    python = site.parents[2] / "bin" / "python"  # site = <env>/lib/python3.X/site-packages
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    env.pop("PYTHONPATH", None)
    return subprocess.run([str(python), "-m", "adaptive_mj", *args], capture_output=True, text=True, env=env,
                          cwd=cwd or REPO, timeout=600)


@pytest.fixture
def on_path(site, monkeypatch):
    monkeypatch.syspath_prepend(str(site))
    return site


def test_list_laws_shows_where_each_comes_from(site):
    r = cli(site, "list", "--laws")
    assert r.returncode == 0, r.stderr
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("emod "))
    assert "plugin from adaptive-mj-emod-law 0.1.0" in line and "keys: lambda [1/s], k [N s/m]" in line
    assert "sliding_adaptive" in r.stdout and "built in" in r.stdout


def test_run_then_replay_verify_is_bit_identical_and_the_log_names_the_plugin(site, bare, tmp_path):
    log = tmp_path / "emod.mcap"
    r = cli(site, "run", str(SCENARIO), "-o", str(log), "--set", "simulation.duration=2", "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["metrics"]["rms_tracking_error_tail"] < 0.05
    r = cli(site, "replay", str(log), "--verify")
    assert r.returncode == 0 and "verify: bit-identical" in r.stdout, r.stdout + r.stderr
    from adaptive_mj.log.replay import read_log

    plugin = read_log(log).header["law_plugin"]
    assert plugin["name"] == "emod" and plugin["distribution"] == "adaptive-mj-emod-law"
    assert plugin["version"] == "0.1.0" and len(plugin["source_sha256"]) == 64
    # without the plugin installed, verify says so instead of failing on the scenario
    env = dict(os.environ, MUJOCO_GL="egl")
    env.pop("PYTHONPATH", None)
    r = subprocess.run([str(bare), "-m", "adaptive_mj", "replay", str(log), "--verify"], capture_output=True,
                       text=True, env=env, cwd=REPO, timeout=600)
    assert "the log's law plugin 'emod' (adaptive-mj-emod-law 0.1.0) is not installed" in r.stdout + r.stderr


def test_sweep_runs_the_plugin_by_name(site, tmp_path):
    out = tmp_path / "sweep"
    r = cli(site, "sweep", str(SCENARIO), "--grid", "nu=0.0,0.05", "--set", "simulation.duration=1",
            "--jobs", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    rows = list(csv_rows(out / "sweep.csv"))
    assert [float(r["law.nu"]) for r in rows] == [0.0, 0.05] and all(r["status"] == "ok" for r in rows)
    assert rows[0]["rms_tracking_error"] != rows[1]["rms_tracking_error"]  # ν changes the run


def csv_rows(path):
    import csv

    with open(path, newline="") as f:
        yield from csv.DictReader(f)


def test_plugin_runs_natively_and_matches_its_python_path(on_path):
    from adaptive_mj import run
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load

    out = []
    for native in (False, True):
        scn = load(SCENARIO, overrides=["simulation.duration=1"])
        s = build(scn)
        out.append(run(s.plant, s.law, s.reference, duration=1.0, theta_hat0=s.theta_hat0, native=native))
    py, nat = out
    assert nat.meta["native"] and not py.meta["native"]
    for f in ("x", "u", "s", "theta_hat"):
        np.testing.assert_array_equal(getattr(nat, f), getattr(py, f), err_msg=f)
    assert np.all(np.isnan(py.V))  # a plugin declares no Lyapunov function
    assert np.abs(py.theta_hat[-1] - py.theta_hat[0]).max() > 0  # it adapts


def test_plugin_runs_compiled_on_the_twin_bit_for_bit(on_path):
    """The plugin's scenario on the analytic twin (plant.backend = "twin"): the twin's compiled loop
    (adaptive_mj.sim.native_chunk) runs the plugin's function and gives the Python path's rows bit for bit."""
    from adaptive_mj import run
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load

    out = []
    for native in (False, True):
        s = build(load(SCENARIO, overrides=["simulation.duration=1", "plant.backend='twin'"]))
        out.append(run(s.plant, s.law, s.reference, duration=1.0, theta_hat0=s.theta_hat0, native=native))
    py, nat = out
    assert nat.meta["native"] and not py.meta["native"]
    for f in ("t", "x", "u", "s", "ref", "theta_hat"):
        np.testing.assert_array_equal(getattr(nat, f), getattr(py, f), err_msg=f)
    assert np.abs(py.theta_hat[-1] - py.theta_hat[0]).max() > 0  # it adapts


def test_a_law_numba_cannot_compile_runs_in_python_with_one_line(on_path, capsys, notes_on_stderr):
    from adaptive_mj import run
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load

    scn = load(SCENARIO, overrides=["law={kind='broken', k=200.0, initial_estimates={d=37.0, b=60.0, c=1.0}}",
                                    "simulation.duration=0.2"])
    s = build(scn)
    traj = run(s.plant, s.law, s.reference, duration=0.2, theta_hat0=s.theta_hat0)
    assert not traj.meta["native"] and traj.status == "ok"
    err = [ln for ln in capsys.readouterr().err.splitlines() if "could not be compiled" in ln]
    assert len(err) == 1 and err[0].startswith("adaptive-mj: note: law plugin 'broken' could not be compiled")
    assert err[0].endswith("running it through the Python callback")


def test_python_callback_flag_forces_the_python_path(on_path):
    from adaptive_mj.setup.scenario import load
    from adaptive_mj.runs.runner import execute

    scn = load(SCENARIO, overrides=["simulation.duration=0.2", "simulation.python_callback=true"])
    assert execute(scn).trajectory.meta["native"] is False


@pytest.mark.parametrize("override, match", [
    ("law.lambda=-1", r"law\.lambda must be > 0\.0, got -1\.0"),
    ("law.gamma=1.0", r"unknown key 'law\.gamma'"),
    ("law={kind='emod', k=1.0, gamma_d=1.0, gamma_p=1.0}", r"law\.lambda is required for law\.kind = 'emod' "
                                                           r"\(adaptive-mj-emod-law 0\.1\.0\): surface slope λ"),
    ("law.kind='emodd'", r"law\.kind must be one of .*'emod'.*, got 'emodd'"),
])
def test_plugin_keys_are_checked_like_built_in_ones(site, override, match):
    r = cli(site, "run", str(SCENARIO), "--set", override, "--set", "simulation.duration=0.1")
    assert r.returncode == 2
    err = r.stderr.strip().splitlines()
    import re

    assert len(err) == 1 and re.search(match, err[0]), err


def test_bench_runs_the_plugin_in_a_section_of_its_own(site, tmp_path, monkeypatch):
    """bench --scenario FILE: the plugin's scenario beside the catalogue (reduced here to that
    section alone), logged and reported."""
    monkeypatch.syspath_prepend(str(site))
    from adaptive_mj.cli import main
    from adaptive_mj.study import bench_catalogue

    monkeypatch.setattr(bench_catalogue, "catalogue", lambda *, quick, logs: [])
    short = tmp_path / "emod_short.toml"
    short.write_text(SCENARIO.read_text().replace("duration = 30.0", "duration = 1.0"))
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "-o", str(out), "--jobs", "1", "--scenario", str(short)]) == 0
    report = (out / "report.md").read_text()
    assert "## Your scenarios" in report and "| `emod_short.toml` | emod | ok |" in report
    assert (out / "logs" / "user-0-emod_short.mcap").stat().st_size > 1000


def test_a_plant_plugin_runs_under_a_built_in_law_and_replays(site, tmp_path):
    """plant.kind = "cart" (an installed plant plugin, its own MJCF and key): the built-in sliding
    law tracks it, compiled into the native callback, identifies d and b from the compiled model's
    truth, and the log replays bit for bit, naming the plant plugin."""
    scn = tmp_path / "cart.toml"
    scn.write_text(CART_SCENARIO)
    log = tmp_path / "cart.mcap"
    r = cli(site, "run", str(scn), "-o", str(log), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["metrics"]["rms_tracking_error_tail"] < 5e-3  # [m], 3 s from d̂ = 1 kg, b̂ = 0
    assert summary["final"]["theta"] == {"d": 2.0, "b": 4.0}  # body mass, and plant.damping applied
    r = cli(site, "replay", str(log), "--verify")
    assert r.returncode == 0 and "bit-identical" in r.stdout, r.stdout + r.stderr
    from adaptive_mj.log.replay import read_log

    header = read_log(log).header
    assert header["plant_plugin"]["name"] == "cart" and header["plant_plugin"]["version"] == "0.2.0"
    assert header["law_plugin"] is None
    r = cli(site, "run", str(scn), "--set", "plant.damping=-1", "--set", "simulation.duration=0.1")
    assert r.returncode == 2 and "plant.damping must be >= 0.0, got -1.0" in r.stderr


def test_native_path_runs_a_plant_plugin(on_path, tmp_path):
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load
    from adaptive_mj.runs.runner import execute

    scn_path = tmp_path / "cart.toml"
    scn_path.write_text(CART_SCENARIO)
    traj = execute(load(scn_path, overrides=["simulation.duration=0.5"])).trajectory
    assert traj.meta["native"] is True and traj.status == "ok"
    assert build(load(scn_path)).plant.true_theta().tolist() == [2.0, 4.0]


def test_a_clean_environment_sees_no_plugin_of_the_test_environment(tmp_path):
    """shared_site_packages hides adaptive-mj and every distribution registering a plugin (here a fake
    site-packages holding a law plugin, an editable plant plugin and an ordinary dependency) and keeps the rest."""
    site = tmp_path / "site"
    for dist, files, entry_points in [
            ("some_dep-1.0", ["some_dep/__init__.py"], ""),
            ("my_law-0.1", ["my_law.py"], "[adaptive_mj.laws]\nmine = my_law:LAW\n"),
            ("my_plant-0.1", ["__editable__.my_plant-0.1.pth", "__editable___my_plant_finder.py"],
             "[adaptive_mj.plants]\nmine = my_plant:PLANT\n"),
            ("adaptive_mj-9.0", ["adaptive_mj/__init__.py"], "")]:
        info = site / f"{dist}.dist-info"
        info.mkdir(parents=True)
        name, version = dist.split("-")
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
        (info / "entry_points.txt").write_text(entry_points)
        (info / "RECORD").write_text("".join(f"{f},,\n" for f in [*files, f"{info.name}/RECORD"]))
        for f in files:
            (site / f).parent.mkdir(parents=True, exist_ok=True)
            (site / f).write_text("")
    shared = shared_site_packages(tmp_path / "shared", sources=[str(site)])
    assert sorted(p.name for p in shared.iterdir()) == ["some_dep", "some_dep-1.0.dist-info"]
    assert all(p.is_symlink() for p in shared.iterdir())


# --- any law on any plant (issue 31) ------------------------------------------------------------------------
def test_a_multi_joint_plugin_runs_compiled_on_the_ur5e_and_replays_with_its_v(site, tmp_path):
    """examples/robust_sl_law, installed by pip: `run ur5e_identification --law robust_sl` runs it in the native
    callback, logs its declared V, and `replay --verify` re-simulates it bit for bit."""
    log = tmp_path / "robust_sl.mcap"
    r = cli(site, "run", "ur5e_identification", "--law", "robust_sl", "--set", "simulation.duration=1",
            "--set", "law.gamma=0.5", "-o", str(log), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["metrics"]["rms_tracking_error_tail"] < 5e-3  # [rad] (2.2e-3 measured; 1 s from π̂ = 0)
    r = cli(site, "replay", str(log), "--verify")
    assert r.returncode == 0 and "verify: bit-identical" in r.stdout, r.stdout + r.stderr
    from adaptive_mj.log.replay import read_log

    back = read_log(log)
    assert back.header["law_plugin"]["name"] == "robust_sl"
    assert back.header["overrides"][0] == "law=robust_sl"  # the log records the law actually run
    V = back.trajectory.V
    assert np.all(np.isfinite(V)) and V[-1] < V[0]  # declared, and it decreases from the start's error


@pytest.mark.parametrize("scenario, extra", [
    ("ur5e_identification.toml", []),
    ("ur5e_drift.toml", ["law.sigma=0.01", "law.dead_zone={width=1e-5, on='tracking_error'}",
                         "law.projection='physical'", "law.ks=2.0"]),
])
def test_multi_joint_plugin_native_equals_python_bit_for_bit(on_path, scenario, extra):
    """The JointLawPlugin through the compiled callback and through the Python one: the same rows and V, with
    the shared modifications (σ, a dead-zone on ‖q̃‖, the physical projection) on as well."""
    from adaptive_mj import run
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, law_swap, load

    out = []
    for native in (False, True):
        s = build(load(SCENARIOS_DIR / scenario, overrides=[law_swap("robust_sl"), "simulation.duration=0.3", *extra]))
        out.append(run(s.plant, s.law, s.reference, duration=0.3, theta_hat0=s.theta_hat0, native=native,
                       noise_std=s.noise_std, rng=s.rng, sensors=s.sensors))
    py, nat = out
    assert nat.meta["native"] and not py.meta["native"]
    for f in ("x", "u", "s", "theta_hat", "V"):
        np.testing.assert_array_equal(getattr(nat, f), getattr(py, f), err_msg=f)
    assert np.all(np.isfinite(py.V)) and np.abs(py.theta_hat[-1] - py.theta_hat[0]).max() > 0


def test_a_per_parameter_gain_table_reaches_the_law_and_v_is_logged(on_path):
    """law.gamma = {d = …, b = …, c = …} of a 1-DOF plugin: laid out in θ order in its params, its V (declared)
    logged, non-increasing over the ideal run's steps to within the integration error, native = Python."""
    from adaptive_mj import run
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, law_swap, load

    over = [law_swap("gtab"), "law.gamma={d=0.0025, b=0.1, c=0.05}", "simulation.duration=2"]
    out = []
    for native in (False, True):
        s = build(load(SCENARIOS_DIR / "heave_tracking.toml", overrides=over))
        np.testing.assert_array_equal(s.law.params, [5.0, 200.0, 0.0025, 0.1, 0.05])
        np.testing.assert_array_equal(s.law.shared.gamma, [0.0025, 0.1, 0.05])  # Γ of the shared leakage
        out.append(run(s.plant, s.law, s.reference, duration=2.0, theta_hat0=s.theta_hat0, native=native))
    assert out[1].meta["native"] and not out[0].meta["native"]
    for f in ("x", "u", "theta_hat", "V"):
        np.testing.assert_array_equal(getattr(out[0], f), getattr(out[1], f), err_msg=f)
    V = out[1].V
    assert np.all(np.isfinite(V)) and np.max(np.diff(V)) <= 1e-6 * V[0]
    with pytest.raises(Exception, match=r"law\.gamma must have the keys d, b, c in that order, got d, c"):
        build(load(SCENARIOS_DIR / "heave_tracking.toml", overrides=[law_swap("gtab"), "law.gamma={d=1.0, c=1.0}"]))
    with pytest.raises(Exception, match=r"law\.gamma\.b must be > 0\.0, got -1"):
        load(SCENARIOS_DIR / "heave_tracking.toml", overrides=[law_swap("gtab"), "law.gamma={d=1.0, b=-1, c=1.0}"])


def test_law_swap_on_a_bundled_scenario_and_in_a_sweep(site, tmp_path):
    """`run heave_tracking --law gtab` (the law's defaults, the scenario's initial estimates kept) and one sweep
    over law.kind = sliding_adaptive, gtab, each law with its own scoped keys."""
    r = cli(site, "run", "heave_tracking", "--law", "gtab", "--set", "simulation.duration=2", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["metrics"]["rms_tracking_error_tail"] < 0.05
    out = tmp_path / "sweep"
    r = cli(site, "sweep", "heave_tracking", "--grid", "law.kind=sliding_adaptive,gtab", "--set",
            "simulation.duration=2", "--set", "law.gtab.k=150", "--jobs", "2", "-o", str(out))
    rows = list(csv_rows(out / "sweep.csv"))
    assert [r["law.kind"] for r in rows] == ["sliding_adaptive", "gtab"], r.stderr
    from adaptive_mj.log.replay import read_log

    logs = sorted((out / "logs").glob("*.mcap"))
    overrides = [read_log(p).header["overrides"] for p in logs]
    assert any("law=gtab" in o and "law.gtab.k=150" in o for o in overrides), overrides
    assert all(r_["rms_tracking_error"] not in ("", "nan") for r_ in rows)


def test_a_law_offered_to_a_plant_it_does_not_serve_is_refused_in_one_line(site):
    r = cli(site, "run", "ur5e_drift", "--law", "emod", "--set", "simulation.duration=0.1")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1, r.stderr
    assert ("law.kind = 'emod' serves the 1-DOF model form" in err[0]
            and "plant.kind = 'manipulator' offers the multi-joint rigid-body form" in err[0]
            and "slotine_li" in err[0] and "robust_sl" in err[0]), err[0]
    r = cli(site, "run", "heave_tracking", "--law", "robust_sl", "--set", "simulation.duration=0.1")
    assert r.returncode == 2 and "laws that serve it: sliding_adaptive, fixed_nominal, robust_sliding" in r.stderr
    r = cli(site, "list", "--laws")
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("robust_sl "))
    assert "serves rigid_body" in line and "gamma[θ] = 0.2" in line and "kd [N m s/rad] = 50" in line
