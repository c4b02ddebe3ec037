"""``command``: any executable as a black-box odometry (a ROS or C++ system, a script...).

Per run adaptune makes a work directory and writes into it:
- ``params.json``: {name: value} of frame 0 (for a constant schedule, the parameters);
- ``schedule.csv``: header ``frame,stamp_ns,<param>...``, one row per frame;
- ``schedule.json``: {"frame": [...], "stamp_ns": [...], "params": {name: [...]}};
- the sequence: the MCAP the scans came from (its path), or ``sequence.mcap`` written there
  when the scans are not read from a file;
- with the ``scans`` option ``kitti`` or ``pcd``, the scans as files too, for a tool that reads
  no MCAP (pipeline/odometry/scan_folder.py): a KITTI-layout folder (``velodyne/NNNNNN.bin``,
  ``times.txt``) or a folder of binary PCD files (``NNNNNN.pcd``, ``times.txt``), in the work
  directory, or written once per sequence into ``scans_cache`` and kept for later runs.
It then runs the argv template ``command`` (a list, or one shell-like string) with these
placeholders substituted: ``{sequence}``, ``{scans}`` (the scans folder; with ``scans: mcap``
the sequence), ``{params}``, ``{schedule}`` (CSV), ``{schedule_json}``,
``{out}`` (the trajectory file the command must write), ``{workdir}``, ``{python}`` (this
interpreter). The command gets ``time_limit_s`` (``run_sequence``'s, else the ``timeout_s``
option); past it its whole process group is killed and TrialTimeout raised. A non-zero exit
status is an OdometryError carrying the last line of its stderr; its stdout is not read
(/dev/null).

The command runs under the guard of ``pipeline.lifetime`` in a process group of its own: when
the run ends early for any reason (time limit, Ctrl-C, SIGTERM, or this process killed, even by
SIGKILL, as the tuner does at a trial's hard time limit) the whole group is killed and the work
directory removed (unless ``keep_workdir``); when the guard itself is killed, this process
kills the group (``pipeline.lifetime.run_guarded``) and the run is an InfrastructureError. A
command that detaches from its process group (``setsid``) is on its own.

The trajectory (T_world_lidar) is read back in ``format``:
- ``kitti``: 12 numbers a line (row-major 3x4), one line per frame in order: N lines for N frames;
- ``tum``: ``stamp_s tx ty tz qx qy qz qw`` a line, matched to frames by stamp (nearest, within
  ``stamp_tolerance_s``); every frame must be present.
Lines starting with ``#`` and blank lines are skipped. The parameter space comes from the
``space`` option: a list of ParamSpec dicts (name, low, high, default, kind, log, unit) or the
path of a YAML/JSON file holding that list (or ``{"params": [...]}``).
"""

from __future__ import annotations

import json
import logging
import os
import shlex
import shutil
import signal
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from pipeline.config import Section
from pipeline.errors import ConfigError, InfrastructureError, OdometryError, TrialTimeout
from pipeline.geometry import pose_from_xyz_quat
from pipeline.io_utils import output_folder, read_input, read_input_text
from pipeline.odometry.base import Adapter, ParameterSpace, ParamSpec, Schedule
from pipeline.odometry.common import F64, parse_options
from pipeline.sequence import Scan, SequenceInfo, SequenceWriter
from pipeline.trajectory import Trajectory

log = logging.getLogger(__name__)

PLACEHOLDERS = ("sequence", "scans", "params", "schedule", "schedule_json", "out", "workdir",
                "python")


class CommandOptions(Section):
    """Settings of ``command``."""

    command: list[str] = Field(min_length=1)
    space: list[dict[str, Any]] | str
    format: Literal["kitti", "tum"] = "kitti"
    timeout_s: float | None = Field(None, gt=0)
    cwd: str | None = None
    workdir: str | None = None
    keep_workdir: bool = False
    stamp_tolerance_s: float = Field(1e-3, gt=0)
    scans: Literal["mcap", "kitti", "pcd"] = "mcap"
    scans_cache: str | None = None

    @field_validator("command", mode="before")
    @classmethod
    def _split(cls, value: object) -> object:
        if isinstance(value, str):
            text = value.strip()
            return json.loads(text) if text.startswith("[") else shlex.split(text)
        return value

    @field_validator("command")
    @classmethod
    def _fields(cls, value: list[str]) -> list[str]:
        import string

        for arg in value:
            for _, field, _, _ in string.Formatter().parse(arg):
                if field is not None and field not in PLACEHOLDERS:
                    raise ValueError(f"unknown placeholder {{{field}}} in {arg!r} "
                                     f"(known: {', '.join(PLACEHOLDERS)})")
        return value


def load_space(spec: list[dict[str, Any]] | str) -> ParameterSpace:
    """ParameterSpace from a list of ParamSpec dicts or a YAML/JSON file of one."""
    from pipeline.json_yaml import parse_yaml

    what = "command option space"
    items: object = spec
    if isinstance(spec, str):
        path = Path(spec)
        text = read_input_text(path, "parameter space file", error=ConfigError, strict=True)
        data = parse_yaml(text, str(path), error=ConfigError)
        what = str(path)
        items = data.get("params") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items:
        raise ConfigError(f"{what}: must be a non-empty list of parameters")
    specs = []
    for i, item in enumerate(items):
        try:
            specs.append(ParamSpec(**item))
        except TypeError as exc:
            raise ConfigError(f"{what}: parameter {i} is malformed ({exc})") from None
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ConfigError(f"{what}: duplicate parameter names in {names}")
    return ParameterSpace(tuple(specs))


class CommandAdapter:
    """The ``command`` adapter: an external executable, parameters in files, trajectory out."""

    name = "command"
    accepts_time_limit = True

    options_model = CommandOptions

    def __init__(self, **options: object) -> None:
        self.options = parse_options(CommandOptions, self.name, dict(options))
        self.space = load_space(self.options.space)

    def run(self, scans: Iterable[Scan], schedule: Schedule,
            time_limit_s: float | None = None) -> Trajectory:
        """Run the command over ``scans`` with ``schedule``; raises OdometryError / TrialTimeout."""
        limit = time_limit_s if time_limit_s is not None else self.options.timeout_s
        base = self.options.workdir
        if base:
            output_folder(base)
        work = Path(tempfile.mkdtemp(prefix="adaptune-cmd-", dir=base))
        try:
            sequence, folder, stamps_ns = self._inputs(scans, work)
            if len(schedule) != len(stamps_ns):
                raise OdometryError(f"command: schedule has {len(schedule)} rows for "
                                    f"{len(stamps_ns)} frames")
            files = write_inputs(work, schedule, stamps_ns)
            argv = [a.format(sequence=sequence, scans=folder, out=work / "trajectory.txt",
                             workdir=work, python=sys.executable, **files)
                    for a in self.options.command]
            run_process(argv, self.options.cwd, limit,
                        workdir=None if self.options.keep_workdir else work)
            T = read_poses(work / "trajectory.txt", self.options.format, stamps_ns,
                           self.options.stamp_tolerance_s)
            return Trajectory(np.arange(len(stamps_ns), dtype=np.int32), stamps_ns, T)
        finally:
            if self.options.keep_workdir:
                log.info("command: work directory kept at %s", work)
            else:
                shutil.rmtree(work, ignore_errors=True)

    def _inputs(self, scans: Iterable[Scan], work: Path) -> tuple[Path, Path, np.ndarray]:
        """(sequence MCAP, scans folder, stamps_ns) of ``scans`` as the ``scans`` option and
        the command's placeholders ask (the folder is the MCAP with ``scans: mcap``)."""
        from pipeline.odometry.scan_folder import scan_folder

        if self.options.scans == "mcap":
            sequence, stamps_ns = self._sequence(scans, work)
            return sequence, sequence, stamps_ns
        from_file = getattr(scans, "path", None) is not None
        wants_sequence = any("{sequence}" in a for a in self.options.command)
        if wants_sequence and not from_file:
            scans = list(scans)  # read twice: into the MCAP and the folder
        folder, stamps_ns = scan_folder(scans, self.options.scans, work,
                                        self.options.scans_cache)
        if wants_sequence or from_file:
            return self._sequence(scans, work)[0], folder, stamps_ns
        return folder, folder, stamps_ns  # {sequence} unused: no MCAP written

    def _sequence(self, scans: Iterable[Scan], work: Path) -> tuple[Path, np.ndarray]:
        """The sequence MCAP holding ``scans`` (theirs, or one written into ``work``) and stamps."""
        path = getattr(scans, "path", None)
        stamps = getattr(scans, "stamps_ns", None)
        if path is not None and stamps is not None and Path(path).is_file():
            return Path(path).resolve(), np.asarray(stamps, np.int64)
        out = work / "sequence.mcap"
        with SequenceWriter(out, SequenceInfo(name="command-input")) as w:
            for scan in scans:
                w.add(scan.stamp_ns, scan.points_lidar, scan.T_world_lidar)
        return out, np.asarray(w.stamps_ns, np.int64)


def write_inputs(work: Path, schedule: Schedule, stamps_ns: np.ndarray) -> dict[str, Path]:
    """params.json, schedule.csv and schedule.json in ``work``; their paths by placeholder."""
    names = list(schedule.values)
    params = work / "params.json"
    params.write_text(json.dumps(schedule.at(0), indent=1))
    csv = work / "schedule.csv"
    csv.write_text(schedule.csv_text(stamps_ns))
    js = work / "schedule.json"
    js.write_text(json.dumps({"frame": schedule.frames.tolist(),
                              "stamp_ns": [int(s) for s in stamps_ns],
                              "params": {n: schedule.values[n].tolist() for n in names}}))
    return {"params": params, "schedule": csv, "schedule_json": js}


def run_process(argv: list[str], cwd: str | None, time_limit_s: float | None,
                workdir: Path | None = None) -> None:
    """Run ``argv`` under the guard (its own process group; killed, and ``workdir`` removed,
    when this call ends early or this process dies); TrialTimeout past the limit,
    InfrastructureError when the guard is killed from outside (the tool's group goes too),
    else OdometryError for a non-zero exit status."""
    from pipeline.lifetime import GUARD_CANNOT_RUN, run_guarded

    try:
        done = run_guarded(argv, cwd, time_limit_s, str(workdir or ""))
    except (FileNotFoundError, NotADirectoryError, PermissionError) as exc:
        raise ConfigError(f"command: cannot run {argv[0]!r} in {cwd or '.'} "
                          f"({exc.strerror})") from None
    except TimeoutError:
        raise TrialTimeout(f"command: {argv[0]} outlived its time limit of {time_limit_s:g} s; "
                           "killed") from None
    err = done.stderr
    if done.guard_signal:
        raise InfrastructureError(f"command: the guard of {Path(argv[0]).name} was killed by "
                                  f"{signal.Signals(done.guard_signal).name}; its process group "
                                  "was killed with it")
    if done.status == GUARD_CANNOT_RUN and err.startswith(b"adaptune guard: "):
        raise ConfigError(f"command: {err.decode(errors='replace').strip()[16:]}")
    if done.status != 0:
        lines = err.decode(errors="replace").strip().splitlines()
        last = lines[-1] if lines else "no stderr"
        raise OdometryError(f"command: {Path(argv[0]).name} exited with status "
                            f"{done.status}: {last}")


def read_poses(path: Path, fmt: str, stamps_ns: np.ndarray, tolerance_s: float) -> F64:
    """(N, 4, 4) T_world_lidar for the N frames at ``stamps_ns`` from a KITTI or TUM file."""
    if not os.path.lexists(path):
        raise OdometryError(f"command: wrote no trajectory ({path.name} missing)")
    try:
        text = read_input(path, "trajectory", error=OdometryError).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise OdometryError(f"command: {path.name} is not UTF-8 text (byte "
                            f"0x{exc.object[exc.start]:02x} at offset {exc.start})") from None
    rows = []
    for k, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            rows.append([float(x) for x in line.replace(",", " ").split()])
        except ValueError:
            raise OdometryError(f"command: {path.name} line {k} is not numbers: "
                                f"{line[:60]!r}") from None
    width = 12 if fmt == "kitti" else 8
    bad = [i for i, r in enumerate(rows) if len(r) != width]
    if bad:
        raise OdometryError(f"command: {path.name} row {bad[0] + 1} has {len(rows[bad[0]])} "
                            f"numbers, a {fmt} trajectory has {width}")
    arr = np.array(rows, np.float64).reshape(-1, width)
    n = len(stamps_ns)
    if fmt == "kitti":
        if len(arr) != n:
            raise OdometryError(f"command: {path.name} has {len(arr)} poses for {n} frames")
        T = np.tile(np.eye(4), (n, 1, 1))
        T[:, :3, :] = arr.reshape(n, 3, 4)
        return T
    return _match_tum(arr, stamps_ns, tolerance_s, path.name)


def _match_tum(arr: F64, stamps_ns: np.ndarray, tolerance_s: float, what: str) -> F64:
    """Poses of a TUM table (M, 8) matched to the frames' stamps (nearest within tolerance)."""
    t_frames = np.asarray(stamps_ns, np.int64) * 1e-9
    order = np.argsort(arr[:, 0], kind="stable")
    t_est = arr[order, 0]
    if len(t_est) == 0:
        raise OdometryError(f"command: {what} is empty")
    j = np.clip(np.searchsorted(t_est, t_frames), 1, max(len(t_est) - 1, 1))
    prev = np.clip(j - 1, 0, len(t_est) - 1)
    j = np.clip(j, 0, len(t_est) - 1)
    nearest = np.where(np.abs(t_est[prev] - t_frames) <= np.abs(t_est[j] - t_frames), prev, j)
    miss = np.abs(t_est[nearest] - t_frames) > tolerance_s
    if miss.any():
        k = int(np.argmax(miss))
        raise OdometryError(f"command: {what} has no pose for frame {k} (stamp "
                            f"{t_frames[k]:.6f} s; {int(miss.sum())} frames missing)")
    rows = arr[order][nearest]
    q = rows[:, 4:8]
    norms = np.linalg.norm(q, axis=1)
    if not np.all(np.isfinite(norms)) or np.any(np.abs(norms - 1.0) > 1e-3):
        k = int(np.argmax(~np.isfinite(norms) | (np.abs(norms - 1.0) > 1e-3)))
        raise OdometryError(f"command: {what} has a non-unit quaternion at frame {k}")
    return pose_from_xyz_quat(rows[:, 1:4], q)


_: type[Adapter] = CommandAdapter
