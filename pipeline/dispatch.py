"""Same numbers on every machine: the process environment that pins what the CPU would choose.

Four libraries pick their code by the CPU they run on, and the last bits of a result follow:
numpy's SIMD dispatch (its AVX2 / AVX-512 loops), OpenBLAS (its kernel, by CPU model, and its
threads, by core count: a product's partial sums), glibc's libm (FMA / AVX variants of exp, log,
pow, sin, cos, tan, atan2: Python's ``math``, numpy without its own SIMD loop, numba's kernels
and the odometry wheels all call it) and numba (the CPU it compiles for). Scan matching is
chaotic in those bits, so a last-bit difference becomes other trials, another fixed set and
other schedules (docs/design.md, "Same numbers on every machine").

Each of them reads its setting once, when it loads (glibc: when the process starts), so the
``adaptune`` command re-executes itself once with ``pinned_environment`` before it imports
anything (``stages.cli.entry``); every process it starts inherits the environment. The pins
are the oldest code path of an x86-64-v2 machine (numpy's own baseline): numpy's baseline loops
only, OpenBLAS's Nehalem kernels on one thread, libm's SSE2 variants, numba's generic target.
``ADAPTUNE_CPU_DISPATCH=native`` opts out (every library picks its fastest code for this CPU;
results then differ between machines in their last bits).

Standard library only: this module runs before numpy may load.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping

MODE_VARIABLE = "ADAPTUNE_CPU_DISPATCH"
"""``portable`` (default: the pins below) or ``native`` (no pins)."""
PORTABLE, NATIVE = "portable", "native"

GLIBC_HWCAPS_OFF = ("AVX", "AVX2", "FMA", "FMA4", "AVX512F")
"""The x86 features glibc's ifunc resolvers may not use (``glibc.cpu.hwcaps`` tunable): libm's
FMA and AVX variants round differently from its SSE2 one."""
X86_PINS = {
    # numpy: only features in this list (and the baseline) may dispatch; SSE2 is part of every
    # x86-64 baseline, so no dispatch target is enabled (NPY_DISABLE_CPU_FEATURES cannot say it:
    # it refuses the baseline's names and ignores unknown ones)
    "NPY_ENABLE_CPU_FEATURES": "SSE2",
    "OPENBLAS_CORETYPE": "Nehalem",
    "OPENBLAS_NUM_THREADS": "1",
    "NUMBA_CPU_NAME": "generic",
}
ARM_PINS = {
    "NPY_ENABLE_CPU_FEATURES": "NEON",
    "OPENBLAS_CORETYPE": "ARMV8",
    "OPENBLAS_NUM_THREADS": "1",
    "NUMBA_CPU_NAME": "generic",
}
UNSET = ("NPY_DISABLE_CPU_FEATURES",)
"""Variables that conflict with a pin (numpy refuses both NPY_*_CPU_FEATURES at once); the
pinned state already disables everything they could."""


def dispatch_mode(environ: Mapping[str, str]) -> str:
    """``portable`` or ``native``, from ``ADAPTUNE_CPU_DISPATCH`` (default portable)."""
    from pipeline.errors import ConfigError

    mode = environ.get(MODE_VARIABLE, PORTABLE).strip().lower() or PORTABLE
    if mode not in (PORTABLE, NATIVE):
        raise ConfigError(f"{MODE_VARIABLE} must be {PORTABLE} or {NATIVE}, got {mode!r}")
    return mode


def pinned_environment(environ: Mapping[str, str],
                       machine: str | None = None) -> dict[str, str] | None:
    """The environment to re-execute in so that every pin holds, or None when ``environ``
    already holds them all, or asks for native dispatch (then it is left as it is).
    ``machine``: ``platform.machine()`` by default."""
    if dispatch_mode(environ) == NATIVE:
        return None
    machine = machine or platform.machine()
    env = dict(environ)
    env.update(_pins(machine))
    for name in UNSET:
        env.pop(name, None)
    if _is_x86(machine):
        env["GLIBC_TUNABLES"] = with_hwcaps_off(environ.get("GLIBC_TUNABLES", ""),
                                                GLIBC_HWCAPS_OFF)
    return None if env == dict(environ) else env


def unpinned_environment(environ: Mapping[str, str],
                         machine: str | None = None) -> dict[str, str]:
    """``environ`` without the pins (variables holding exactly a pinned value, the hwcaps
    entries of ``GLIBC_TUNABLES``) and with ``ADAPTUNE_CPU_DISPATCH=native``: for a process
    that a pinned one starts to run as this machine is (the bench's native runs)."""
    machine = machine or platform.machine()
    env = {k: v for k, v in environ.items() if _pins(machine).get(k) != v}
    if _is_x86(machine) and "GLIBC_TUNABLES" in env:
        env["GLIBC_TUNABLES"] = without_hwcaps_off(env["GLIBC_TUNABLES"], GLIBC_HWCAPS_OFF)
        if not env["GLIBC_TUNABLES"]:
            del env["GLIBC_TUNABLES"]
    return {**env, MODE_VARIABLE: NATIVE}


def _pins(machine: str) -> dict[str, str]:
    return ARM_PINS if machine in ("aarch64", "arm64") else X86_PINS


def _is_x86(machine: str) -> bool:
    return machine in ("x86_64", "AMD64", "amd64")


def with_hwcaps_off(tunables: str, features: tuple[str, ...]) -> str:
    """``GLIBC_TUNABLES`` (``name=value:name=value``) with ``-F`` for every feature F in its
    ``glibc.cpu.hwcaps`` list, the other tunables and entries kept in their order."""
    entries = [e for e in tunables.split(":") if e]
    key = "glibc.cpu.hwcaps"
    current = next((e.split("=", 1)[1] for e in entries if e.split("=", 1)[0] == key), "")
    caps = [c for c in current.split(",") if c]
    caps += [f"-{f}" for f in features if f"-{f}" not in caps]
    kept = [e for e in entries if e.split("=", 1)[0] != key]
    return ":".join([*kept, f"{key}={','.join(caps)}"])


def without_hwcaps_off(tunables: str, features: tuple[str, ...]) -> str:
    """``GLIBC_TUNABLES`` without the ``-F`` entries ``with_hwcaps_off`` adds (a
    ``glibc.cpu.hwcaps`` left empty goes too)."""
    key, drop = "glibc.cpu.hwcaps", {f"-{f}" for f in features}
    out = []
    for entry in (e for e in tunables.split(":") if e):
        name, _, value = entry.partition("=")
        if name == key:
            caps = [c for c in value.split(",") if c and c not in drop]
            if caps:
                out.append(f"{key}={','.join(caps)}")
        else:
            out.append(entry)
    return ":".join(out)


def is_pinned(environ: Mapping[str, str] | None = None) -> bool:
    """Whether ``environ`` (this process's by default) holds every pin."""
    environ = os.environ if environ is None else environ
    return dispatch_mode(environ) == PORTABLE and pinned_environment(environ) is None


def dispatch_state() -> dict[str, object]:
    """What this process runs with (loads numpy, numba and threadpoolctl): numpy's enabled
    dispatch targets, each OpenBLAS's kernel and threads, numba's target CPU, the mode."""
    import numba
    import numpy as np  # noqa: F401 - loads OpenBLAS for threadpoolctl
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    from threadpoolctl import threadpool_info

    blas = [{"library": info.get("prefix"), "core": info.get("architecture"),
             "threads": info.get("num_threads")}
            for info in threadpool_info() if info.get("user_api") == "blas"]
    return {"mode": dispatch_mode(os.environ),
            "numpy_dispatch": [f for f in __cpu_dispatch__ if __cpu_features__.get(f)],
            "openblas": blas,
            "numba_cpu": getattr(numba.config, "CPU_NAME", None) or "host"}
