"""The same numbers on every machine (docs/design.md, "Same numbers on every machine").

A small simulate, descriptors, trials, rte, surrogate and select run by the ``adaptune``
executable, once as this machine is and once under each setting that makes this CPU look like
another one to a library that chooses its code by the CPU: numpy's best dispatch target off,
an older OpenBLAS kernel, numba's generic target, glibc's libm without FMA. Every output must
have the same bytes. Each setting is shown to take effect (an unknown feature name would be
ignored silently): it changes what the library reports when adaptune does not pin the dispatch
(``ADAPTUNE_CPU_DISPATCH=native``), and there it changes the simulated scans, which is what the
pins are for. Last, the ray caster on another CPU model altogether (qemu's user-mode emulation
of a Haswell: its own CPUID, so Embree picks its kernels for that CPU, and its own approximate
reciprocals): the same scans.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.dispatch import (
    GLIBC_HWCAPS_OFF,
    MODE_VARIABLE,
    pinned_environment,
    unpinned_environment,
    with_hwcaps_off,
)

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
ADAPTUNE = str(BIN / "adaptune")
X86 = os.uname().machine == "x86_64"
LD_SO = Path("/lib64/ld-linux-x86-64.so.2")

STEPS = [
    ["simulate-set", "--out", "seq"],
    ["descriptors", "--sequences", "seq", "--out", "d.parquet", "--environment", "e.parquet",
     "--pca", "pca"],
    ["trials", "--sequences", "seq", "--out", "trials"],
    ["rte", "--sequences", "seq", "--trials", "trials", "--descriptors", "d.parquet",
     "--environment", "e.parquet", "--db", "results.duckdb"],
    ["surrogate", "--db", "results.duckdb", "--pca", "pca", "--out", "model", "--trials",
     "trials"],
    ["select", "model", "seq/street_0.mcap", "--out", "schedule.parquet"],
    ["run", "--algorithm", "gicp", "seq/street_0.mcap", "--out", "gicp.parquet"],
    ["run", "--algorithm", "kiss_icp", "seq/street_0.mcap", "--out", "kiss_icp.parquet"],
]
"""The commands run, in order; the compiled odometry wheels (small_gicp, kiss_icp) too."""


def tiny_params() -> dict[str, Any]:
    """params.yaml with two 16-frame VLP-16 worlds, three trials each, L = 2 m."""
    p = yaml.safe_load((REPO / "params.yaml").read_text())
    p["base"]["length_m"] = 2.0
    p["simulate"].update(sensor="vlp16", train={"street": 1, "cave": 1}, train_frames=16,
                         validation_count=0, workers=1)
    p["descriptors"].update(workers=1, pca_dim=3, range_bins=2)
    p["trials"].update(iterations=3, workers=1, startup_trials=2)
    p["surrogate"].update(n_sobol=8, cv_max_frames=10)
    return p


def clean_env(**extra: str) -> dict[str, str]:
    """This process's environment without the pins (`make test` runs pinned) and without a
    dispatch mode (portable, the default), plus ``extra``."""
    env = unpinned_environment(os.environ)
    del env[MODE_VARIABLE]
    return {**env, **extra}


def run_pipeline(folder: Path, env: dict[str, str], steps: list[list[str]] = STEPS) -> str:
    """The steps in ``folder`` (its params.yaml: ``tiny_params``), one process started by
    ``adaptune exec`` (pinned as every ``adaptune`` process is: helpers/run_steps.py); SHA-256
    of every output's path and bytes."""
    folder.mkdir(parents=True)
    (folder / "params.yaml").write_text(yaml.safe_dump(tiny_params(), sort_keys=False))
    done = subprocess.run(
        [ADAPTUNE, "exec", "--", sys.executable, "-m", "helpers.run_steps", json.dumps(steps)],
        cwd=folder, env={**env, "PYTHONPATH": str(Path(__file__).parent)}, capture_output=True,
        text=True, timeout=900)
    assert done.returncode == 0, f"{steps}: {done.stderr}"
    digest = hashlib.sha256()
    for f in sorted(p for p in folder.rglob("*") if p.is_file() and p.name != "params.yaml"):
        digest.update(f"{f.relative_to(folder).as_posix()}\0".encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


def reported(env: dict[str, str]) -> dict[str, Any]:
    """What a process started by ``adaptune exec`` with ``env`` runs with: numpy's enabled
    dispatch targets, each OpenBLAS's kernel, numba's target and whether glibc lets libm use
    FMA (bit 12 of CPUID leaf 1's ECX among the features ld.so lets programs use)."""
    code = ("import json; from pipeline.dispatch import dispatch_state; "
            "print(json.dumps(dispatch_state()))")
    done = subprocess.run([ADAPTUNE, "exec", "--", sys.executable, "-c", code], env=env,
                          capture_output=True, text=True, timeout=300, check=True)
    state = json.loads(done.stdout)
    state["glibc_fma"] = glibc_fma(env) if LD_SO.exists() else None
    return state


def glibc_fma(env: dict[str, str]) -> bool:
    """Whether ld.so, started by ``adaptune exec`` with ``env``, lets libm's ifuncs use FMA."""
    done = subprocess.run([ADAPTUNE, "exec", "--", str(LD_SO), "--list-diagnostics"], env=env,
                          capture_output=True, text=True, timeout=60, check=True)
    key = "x86.cpu_features.features[0x0].active[0x2]="
    line = next(x for x in done.stdout.splitlines() if x.startswith(key))
    return bool(int(line.split("=")[1], 16) & (1 << 12))


def cpu_settings(native: dict[str, Any]) -> dict[str, dict[str, str]]:
    """Settings that make this CPU look older to each library, from what it reports
    natively: numpy's best enabled dispatch target off, OpenBLAS's Sandybridge kernel (or
    Core2 where Sandybridge is what it chose), numba's generic target, libm without FMA."""
    out: dict[str, dict[str, str]] = {}
    if native["numpy_dispatch"]:
        out["numpy"] = {"NPY_DISABLE_CPU_FEATURES": native["numpy_dispatch"][-1]}
    cores = {b["core"] for b in native["openblas"]}
    out["openblas"] = {"OPENBLAS_CORETYPE": "Core2" if "Sandybridge" in cores else "Sandybridge"}
    out["numba"] = {"NUMBA_CPU_NAME": "generic"}
    if native["glibc_fma"]:
        out["glibc"] = {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-FMA,-AVX2"}
    return out


@pytest.fixture(scope="module")
def native_state() -> dict[str, Any]:
    return reported(clean_env(ADAPTUNE_CPU_DISPATCH="native"))


@pytest.mark.skipif(not X86, reason="the settings are x86-64's")
def test_every_setting_changes_what_a_library_runs_with_unless_adaptune_pins_it(
        native_state: dict[str, Any]) -> None:
    pinned = reported(clean_env())
    assert pinned["numpy_dispatch"] == [] and pinned["numba_cpu"] == "generic"
    assert {b["core"] for b in pinned["openblas"]} == {"Nehalem"}
    assert {b["threads"] for b in pinned["openblas"]} == {1}
    assert pinned["glibc_fma"] in (False, None)
    for name, setting in cpu_settings(native_state).items():
        native = reported(clean_env(ADAPTUNE_CPU_DISPATCH="native", **setting))
        assert native != native_state, f"{name}: {setting} changed nothing"
        assert reported(clean_env(**setting)) == pinned, name


@pytest.mark.skipif(not X86, reason="the settings are x86-64's")
def test_a_small_pipeline_gives_the_same_bytes_under_every_setting(
        tmp_path: Path, native_state: dict[str, Any]) -> None:
    settings = cpu_settings(native_state)
    assert len(settings) >= 3, settings
    reference = run_pipeline(tmp_path / "reference", clean_env())
    for name, setting in settings.items():
        assert run_pipeline(tmp_path / name, clean_env(**setting)) == reference, name


@pytest.mark.skipif(not X86, reason="the settings are x86-64's")
def test_without_the_pins_a_setting_changes_the_simulated_scans(
        tmp_path: Path, native_state: dict[str, Any]) -> None:
    """What the pins are for: numpy's dispatch alone moves the scans' last bits."""
    setting = cpu_settings(native_state).get("numpy") or cpu_settings(native_state)["glibc"]
    simulate = STEPS[:1]
    a = run_pipeline(tmp_path / "a", clean_env(ADAPTUNE_CPU_DISPATCH="native"), simulate)
    b = run_pipeline(tmp_path / "b", clean_env(ADAPTUNE_CPU_DISPATCH="native", **setting),
                     simulate)
    assert a != b


def test_the_pinned_environment_is_reached_once_and_keeps_other_settings() -> None:
    env = {"PATH": "/bin", "GLIBC_TUNABLES": "glibc.malloc.check=0",
           "NPY_DISABLE_CPU_FEATURES": "AVX512F", "OPENBLAS_CORETYPE": "Haswell"}
    pinned = pinned_environment(env, machine="x86_64")
    assert pinned is not None and pinned["PATH"] == "/bin"
    assert "NPY_DISABLE_CPU_FEATURES" not in pinned  # numpy refuses both variables at once
    assert pinned["OPENBLAS_CORETYPE"] == "Nehalem"
    assert pinned["GLIBC_TUNABLES"] == with_hwcaps_off("glibc.malloc.check=0", GLIBC_HWCAPS_OFF)
    assert pinned["GLIBC_TUNABLES"].startswith("glibc.malloc.check=0:glibc.cpu.hwcaps=-AVX,")
    assert pinned_environment(pinned, machine="x86_64") is None  # no second re-execution
    assert pinned_environment({**env, MODE_VARIABLE: "native"}, machine="x86_64") is None
    native = unpinned_environment(pinned, machine="x86_64")
    assert native == {"PATH": "/bin", "GLIBC_TUNABLES": "glibc.malloc.check=0",
                      MODE_VARIABLE: "native"}


def test_an_unknown_dispatch_mode_is_one_line() -> None:
    done = subprocess.run([ADAPTUNE, "--help"], env=clean_env(ADAPTUNE_CPU_DISPATCH="fast"),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert done.stderr.strip() == ("adaptune: error: ADAPTUNE_CPU_DISPATCH must be portable or "
                                   "native, got 'fast'")


SCAN_SCRIPT = """
import hashlib, numpy as np
from pipeline.sim.simulate import SimSpec, iter_scans, make_world
spec = SimSpec(world="street", seed=7, frames=2, sensor="vlp16")
scans = iter_scans(make_world(spec), spec.sensor_model(), spec.seed, motion=spec.motion)
print(hashlib.sha256(np.concatenate([s.points_lidar for s in scans]).tobytes()).hexdigest())
"""


@pytest.mark.skipif(not X86, reason="qemu-x86_64 emulates an x86-64 CPU")
def test_the_ray_caster_gives_the_same_scans_on_an_emulated_cpu() -> None:
    qemu = shutil.which("qemu-x86_64")
    if qemu is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("qemu-x86_64 not found: make setup installs qemu-user")
        pytest.skip("qemu-x86_64 not found (Debian's qemu-user; make setup installs it)")

    def scans(*prefix: str) -> str:
        done = subprocess.run([ADAPTUNE, "exec", "--", *prefix, sys.executable, "-c",
                               SCAN_SCRIPT], env=clean_env(), capture_output=True, text=True,
                              timeout=1800)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    native = scans()  # first: compiles and caches the kernels (generic: qemu reuses them)
    assert scans(qemu, "-cpu", "Haswell-noTSX") == native
