"""The black-box contract (docs/design.md, "Contracts"): parameter spaces, schedules,
adapters.

An *adapter* wraps one odometry algorithm. It declares a ``ParameterSpace`` (the baseline is
each parameter's default) and runs over scans with fixed parameters or a per-frame
``Schedule``. In-process adapters implement ``start`` (a streaming ``Odometry`` that takes
one scan at a time and accepts new parameters between scans); ``run_streaming`` turns that
into ``run``. Out-of-process adapters (``command``) implement ``run`` directly.

An adapter may also offer ``warm(scans: list[Scan]) -> None`` (``WarmableAdapter``): precompute
what depends only on the scans and its untuned options (``ndt``: the downsampled source clouds).
The tuner calls it once per worker and set of sequences, before the trials; results must be
bitwise the same with and without it. The optional capabilities (``StreamingAdapter``,
``WarmableAdapter``, ``TimeLimitedAdapter``) are runtime-checkable Protocols.
"""

from __future__ import annotations

import itertools
import json
import math
import numbers
from collections.abc import Callable, Generator, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError, InputError
from pipeline.sequence import Scan
from pipeline.trajectory import Trajectory
from pipeline.unit_cube import UnitCube

Params = dict[str, float]
"""Parameter name -> value (ints are stored as floats with integral values)."""


@dataclass(frozen=True)
class ParamSpec:
    """One tunable parameter: range [low, high], int or float, log scale, baseline default."""

    name: str
    low: float
    high: float
    default: float
    kind: Literal["float", "int"] = "float"
    log: bool = False
    unit: str = ""

    def __post_init__(self) -> None:
        if not self.low <= self.default <= self.high:
            raise ConfigError(
                f"{self.name}: default {self.default} outside [{self.low}, {self.high}]"
            )
        if self.log and self.low <= 0:
            raise ConfigError(f"{self.name}: log scale needs low > 0, got low={self.low}")

    def check(self, value: object) -> float:
        """``value`` as a float if it is a finite number in range (and integral for ints);
        else ConfigError. Strings, lists, null and booleans (``true`` is not 1.0) are refused."""
        if not isinstance(value, numbers.Real) or isinstance(value, bool | np.bool_):
            shown = json.dumps(value) if isinstance(value, str | bool | None) else repr(value)
            raise ConfigError(f"{self.name} must be a number, got {shown} "
                              f"({type(value).__name__})")
        v = float(value)
        if not math.isfinite(v) or not self.low <= v <= self.high:
            raise ConfigError(f"{self.name} must be in [{self.low}, {self.high}], got {value}")
        if self.kind == "int" and v != round(v):
            raise ConfigError(f"{self.name} must be an integer, got {value}")
        return v


def _changed(spec: ParamSpec, new: Mapping[str, object], what: str) -> ParamSpec:
    """``spec`` with the fields of ``new`` replaced, checked (ConfigError naming ``what``)."""
    from dataclasses import replace

    for key in ("low", "high", "default"):
        value = new.get(key, getattr(spec, key))
        if not isinstance(value, numbers.Real) or isinstance(value, bool) \
                or not math.isfinite(float(value)):
            raise ConfigError(f"{what}.{key} must be a finite number, got {value!r}")
    log = new.get("log", spec.log)
    if not isinstance(log, bool):
        raise ConfigError(f"{what}.log must be true or false, got {log!r}")
    low, high = float(new.get("low", spec.low)), float(new.get("high", spec.high))  # type: ignore[arg-type]
    default = float(new.get("default", spec.default))  # type: ignore[arg-type]
    if not low < high:
        raise ConfigError(f"{what}: high must be > low, got (low={low:g}, high={high:g})")
    if spec.kind == "int" and not all(v == round(v) for v in (low, high, default)):
        raise ConfigError(f"{what}: an integer parameter needs integral low, high and default, "
                          f"got (low={low:g}, high={high:g}, default={default:g})")
    if not low <= default <= high:
        raise ConfigError(f"{what}: default must be in [low, high], got (low={low:g}, "
                          f"high={high:g}, default={default:g})")
    if log and low <= 0:
        raise ConfigError(f"{what}: log scale needs low > 0, got low={low:g}")
    return replace(spec, low=low, high=high, default=default, log=log)


def grid_sets(grid: Mapping[str, Sequence[float]]) -> list[Params]:
    """Every combination of the grid's values (parameter name -> its values), its first
    parameter varying slowest."""
    names = list(grid)
    return [dict(zip(names, values, strict=True))
            for values in itertools.product(*grid.values())]


@dataclass(frozen=True)
class ParameterSpace:
    """The ordered parameters of an adapter."""

    specs: tuple[ParamSpec, ...]

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.specs]

    def defaults(self) -> Params:
        """The baseline: every parameter at its default."""
        return {s.name: float(s.default) for s in self.specs}

    def __getitem__(self, name: str) -> ParamSpec:
        for s in self.specs:
            if s.name == name:
                return s
        raise ConfigError(f"unknown parameter {name!r} (known: {', '.join(self.names)})")

    def validate(self, params: Mapping[str, float], partial: bool = False) -> Params:
        """Checked copy of ``params``; missing names take defaults unless ``partial``."""
        unknown = set(params) - set(self.names)
        if unknown:
            raise ConfigError(
                f"unknown parameter {sorted(unknown)[0]!r} (known: {', '.join(self.names)})"
            )
        out = {} if partial else self.defaults()
        out.update({k: self[k].check(v) for k, v in params.items()})
        return out

    def distinct(self, sets: Iterable[Mapping[str, float]]) -> list[Params]:
        """``sets`` validated (``validate``: a missing parameter at its default; ConfigError
        naming a value out of range), the first of equal ones kept, in order."""
        out: list[Params] = []
        for params in sets:
            checked = {k: float(v) for k, v in self.validate(params).items()}
            if checked not in out:
                out.append(checked)
        return out

    @property
    def unit_cube(self) -> UnitCube:
        """The mapping of these parameters to [0, 1]^D (log parameters on a log scale)."""
        return UnitCube.of(self.specs)

    def to_unit(self, params: Mapping[str, float]) -> NDArray[np.float64]:
        """Map params to [0, 1]^D (``UnitCube.to_unit``). (D,) float64."""
        cube = self.unit_cube
        return cube.to_unit(cube.values(params))[0]

    def from_unit(self, u: NDArray[np.float64]) -> Params:
        """Inverse of ``to_unit`` (clipped to [0, 1], ints rounded; ``UnitCube.from_unit``)."""
        cube = self.unit_cube
        return cube.params(cube.from_unit(u)[0])

    def to_json(self) -> list[dict[str, object]]:
        """Plain description (for manifests and reports)."""
        return [dict(name=s.name, low=s.low, high=s.high, default=s.default, kind=s.kind,
                     log=s.log, unit=s.unit) for s in self.specs]

    @classmethod
    def from_json(cls, items: Iterable[Mapping[str, object]], what: str = "space"
                  ) -> ParameterSpace:
        """The inverse of ``to_json``; ConfigError naming ``what`` when an item is malformed."""
        specs = []
        for i, item in enumerate(items):
            try:
                specs.append(ParamSpec(**item))  # type: ignore[arg-type]
            except TypeError as exc:
                raise ConfigError(f"{what}: parameter {i} is malformed ({exc})") from None
        return cls(tuple(specs))

    def override(self, changes: Mapping[str, Mapping[str, object]],
                 what: str = "trials.space") -> ParameterSpace:
        """This space with some ranges changed: ``changes`` maps a parameter name to any of
        ``low``, ``high``, ``default``, ``log`` (the rest is kept). ConfigError, naming
        ``what``, the parameter and the rule, for an unknown name or a range that breaks a
        rule (low < high, low <= default <= high, log needs low > 0, integral bounds and
        default for ints)."""
        unknown = sorted(set(changes) - set(self.names))
        if unknown:
            raise ConfigError(f"{what}: unknown parameter {unknown[0]!r} (known: "
                              f"{', '.join(self.names)})")
        specs = []
        for spec in self.specs:
            new = {k: v for k, v in (changes.get(spec.name) or {}).items() if v is not None}
            bad = sorted(set(new) - {"low", "high", "default", "log"})
            if bad:
                raise ConfigError(f"{what}.{spec.name}: {bad[0]!r} cannot be set (low, high, "
                                  "default, log)")
            specs.append(_changed(spec, new, f"{what}.{spec.name}"))
        return ParameterSpace(tuple(specs))


@dataclass
class Schedule:
    """Parameters per frame. ``values``: name -> (N,) float64, aligned with ``frames`` (N,);
    ``source``: the file it was read from (what its errors name), if any."""

    frames: NDArray[np.int32]
    values: dict[str, NDArray[np.float64]]
    stamps_ns: NDArray[np.int64] | None = None
    source: str | None = None

    @classmethod
    def constant(cls, params: Mapping[str, float], n_frames: int) -> Schedule:
        """The same parameters for frames 0..n_frames-1."""
        return cls(np.arange(n_frames, dtype=np.int32),
                   {k: np.full(n_frames, float(v)) for k, v in params.items()})

    def __len__(self) -> int:
        return len(self.frames)

    def at(self, i: int) -> Params:
        """Parameters of the i-th row."""
        return {k: float(v[i]) for k, v in self.values.items()}

    def changes(self) -> list[int]:
        """Row indices where any parameter differs from the previous row (0 always)."""
        if not len(self):
            return []
        arr = np.stack(list(self.values.values()), axis=1)
        diff = np.any(arr[1:] != arr[:-1], axis=1)
        return [0, *(np.flatnonzero(diff) + 1).tolist()]

    @property
    def n_changes(self) -> int:
        """Parameter changes after the first frame: the ``set_params`` calls a run makes (what
        ``select``, ``live``, ``adaptive`` and the report count)."""
        return max(len(self.changes()) - 1, 0)

    def validate(self, space: ParameterSpace, n_frames: int, what: str = "schedule") -> None:
        """InputError unless the schedule covers frames 0..n_frames-1 with valid values; it
        names the schedule's file (``source``) and the sequence ``what`` it is meant for."""
        who, of = (self.source, f" (for {what})") if self.source else (what, "")
        if len(self) != n_frames or not np.array_equal(self.frames, np.arange(n_frames)):
            raise InputError(f"{who}: covers {len(self)} frames, the sequence has {n_frames}"
                             f"{of}")
        if set(self.values) != set(space.names):
            raise InputError(f"{who}: parameters {sorted(self.values)}, expected "
                             f"{space.names}{of}")
        for name, arr in self.values.items():
            spec = space[name]
            bad = ~np.isfinite(arr) | (arr < spec.low) | (arr > spec.high)
            if bad.any():
                k = int(np.argmax(bad))
                raise InputError(f"{who}: {name} must be in [{spec.low}, {spec.high}], "
                                 f"got {arr[k]} at frame {k}{of}")

    def csv_text(self, stamps_ns: NDArray[np.int64] | None = None) -> str:
        """The schedule as CSV: header ``frame,stamp_ns,<param>...``, one row a frame, values
        as Python writes floats (round-trip exact); stamps ``stamps_ns`` or the schedule's."""
        stamps = self._stamps(stamps_ns)
        names = list(self.values)
        rows = ["frame,stamp_ns," + ",".join(names)]
        for i in range(len(self)):
            vals = ",".join(repr(float(self.values[n][i])) for n in names)
            rows.append(f"{int(self.frames[i])},{int(stamps[i])},{vals}")
        return "\n".join(rows) + "\n"

    def _stamps(self, stamps_ns: NDArray[np.int64] | None = None) -> NDArray[np.int64]:
        if stamps_ns is not None:
            return np.asarray(stamps_ns, np.int64)
        return self.stamps_ns if self.stamps_ns is not None else np.zeros(len(self), np.int64)

    def write(self, path: str | Path) -> None:
        """Write as Parquet (schemas.arrow.schedule_schema), or as CSV (``csv_text``) when
        ``path`` ends in .csv, atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from pipeline.io_utils import atomic_path, atomic_write_text
        from schemas.arrow import schedule_schema

        if Path(path).suffix.lower() == ".csv":
            atomic_write_text(path, self.csv_text())
            return
        names = list(self.values)
        stamps = self._stamps()
        cols = [pa.array(self.frames, pa.int32()), pa.array(stamps, pa.int64())]
        cols += [pa.array(self.values[n], pa.float64()) for n in names]
        table = pa.Table.from_arrays(cols, schema=schedule_schema(names))
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)

    @classmethod
    def read(cls, path: str | Path) -> Schedule:
        """Read a schedule written by ``write``."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from pipeline.schema_version import check_schema_version

        path = Path(path)
        try:
            table = pq.read_table(path)
        except (FileNotFoundError, pa.ArrowInvalid, OSError) as exc:
            raise InputError(f"{path}: not a readable schedule ({exc})") from exc
        check_schema_version(table.schema, str(path))
        missing = [c for c in ("frame", "stamp_ns") if c not in table.column_names]
        if missing:
            raise InputError(f"{path}: a schedule needs the columns frame and stamp_ns, "
                             f"{' and '.join(missing)} missing")
        types = {f.name: f.type for f in table.schema}
        for name, kind in types.items():
            if not (pa.types.is_integer(kind) or pa.types.is_floating(kind)):
                raise InputError(f"{path}: schedule column {name} must be numeric, got {kind}")
            if table.column(name).null_count:
                raise InputError(f"{path}: schedule column {name} has missing values")
        names = [c for c in table.column_names if c not in ("frame", "stamp_ns")]
        return cls(_integers(table.column("frame").to_numpy(), np.int32, "frame", path),
                   {n: table.column(n).to_numpy().astype(np.float64) for n in names},
                   _integers(table.column("stamp_ns").to_numpy(), np.int64, "stamp_ns", path),
                   str(path))


def _integers(values: NDArray[Any], dtype: type[np.signedinteger[Any]], name: str,
              path: Path) -> NDArray[Any]:
    """``values`` as ``dtype``; InputError naming the column and the first value that is not a
    whole number in its range (a float column of 1.5 or 2**31 is not cast to a wrong frame)."""
    info = np.iinfo(dtype)
    if values.dtype.kind in "iu":
        bad = (values < info.min) | (values > info.max)
    else:
        # float: whole and exactly representable; 2**63 is not an int64, beyond float's grain
        bad = ~np.isfinite(values) | (values != np.round(values)) | \
            (values < info.min) | (values >= -float(info.min))
    if bad.any():
        raise InputError(f"{path}: schedule column {name} must hold whole numbers in "
                         f"[{info.min}, {info.max}], got {values[bad][0].item()!r}")
    return values.astype(dtype)


@runtime_checkable
class Odometry(Protocol):
    """A running odometry: one scan at a time, parameters replaceable between scans."""

    def step(self, points_lidar: NDArray[np.float32], stamp_ns: int) -> NDArray[np.float64]:
        """Register one scan ((N, 3) float32, sensor frame [m]); return T_world_lidar (4, 4)."""
        ...

    def set_params(self, params: Params) -> None:
        """Apply new parameters from the next scan on (in place, or rebuilt with state
        handed over)."""
        ...


@runtime_checkable
class Adapter(Protocol):
    """One odometry algorithm behind the black-box contract: what every caller may use.

    The optional capabilities below are Protocols of their own; callers test them with
    ``isinstance`` (``StreamingAdapter``, ``WarmableAdapter``, ``TimeLimitedAdapter``).
    """

    name: str
    space: ParameterSpace

    def run(self, scans: Iterable[Scan], schedule: Schedule) -> Trajectory:
        """Run over ``scans`` (frames 0..N-1) with parameters per frame; a Trajectory of N poses."""
        ...


def with_space(adapter: Adapter, space: ParameterSpace) -> Adapter:
    """``adapter`` searching and accepting ``space`` instead of its built-in ranges (the one a
    study used, ``trials.space``): same names, order and kinds; ConfigError otherwise."""
    built_in = adapter.space
    if [(s.name, s.kind) for s in space.specs] != [(s.name, s.kind) for s in built_in.specs]:
        raise ConfigError(f"{adapter.name}: the parameter space {space.names} does not match "
                          f"the adapter's {built_in.names}")
    adapter.space = space
    return adapter


@runtime_checkable
class StreamingAdapter(Adapter, Protocol):
    """An in-process adapter that streams: ``start`` gives an ``Odometry`` that takes one scan
    at a time and new parameters between scans (``run_streaming``, ``adaptune live``)."""

    def start(self, params: Params) -> Odometry:
        """A running odometry with ``params`` (validated; missing ones take the defaults)."""
        ...


@runtime_checkable
class WarmableAdapter(Adapter, Protocol):
    """An adapter with work that depends only on the scans and its untuned options (module
    docstring): the tuner calls ``warm`` once per worker and set of sequences."""

    def warm(self, scans: list[Scan]) -> None:
        """Precompute for ``scans``; results must be bitwise the same with and without it."""
        ...


@runtime_checkable
class TimeLimitedAdapter(Adapter, Protocol):
    """An adapter that enforces a time limit itself (an external process it can kill):
    ``run_sequence`` hands it the limit instead of checking between frames."""

    accepts_time_limit: bool

    def run(self, scans: Iterable[Scan], schedule: Schedule,  # type: ignore[override]
            time_limit_s: float | None = None) -> Trajectory:
        """``Adapter.run`` that raises TrialTimeout past ``time_limit_s`` seconds."""
        ...


def run_streaming(make: Callable[[Params], Odometry], scans: Iterable[Scan],
                  schedule: Schedule) -> Trajectory:
    """``run`` for in-process adapters: ``make(params)`` -> Odometry, then step every scan
    (``stream_poses``)."""
    frames, stamps, poses = [], [], []
    for scan, pose in stream_poses(make, scans, schedule):
        poses.append(pose)
        frames.append(scan.frame)
        stamps.append(scan.stamp_ns)
    return Trajectory(np.array(frames), np.array(stamps), np.stack(poses))


def stream_poses(make: Callable[[Params], Odometry], scans: Iterable[Scan], schedule: Schedule
                 ) -> Generator[tuple[Scan, NDArray[np.float64]], None, None]:
    """(scan, T_world_lidar (4, 4)) of every scan in turn: ``make(params)`` -> Odometry on
    the first, ``set_params`` only where the schedule changes; a caller that stops early (the
    tuner at a checkpoint) runs no further scan. InputError when there is no scan."""
    changes = set(schedule.changes())
    odom: Odometry | None = None
    for i, scan in enumerate(scans):
        if odom is None:
            odom = make(schedule.at(i))
        elif i in changes:
            odom.set_params(schedule.at(i))
        if scan.time_s is not None and getattr(odom, "deskews", False):  # kiss_icp: per-point time
            yield scan, odom.step(scan.xyz, scan.stamp_ns, time_s=scan.time_s)  # type: ignore[call-arg]
        else:
            yield scan, odom.step(scan.xyz, scan.stamp_ns)
    if odom is None:
        raise InputError("no scans to run odometry on")
