"""Atomic writes and read-ahead.

Every output adaptune writes goes through ``atomic_path`` (a file) or ``atomic_dir`` (a folder):
on any error the previous output stays byte-identical and no temporary remains; a killed
writer's temporary (``.<name>.<pid>.<hex>.tmp``) is removed by the next write of the same
output; files and folders get the umask's permissions.

An output that is no regular file is written through, never replaced (docs/design.md,
"Outputs"): a character device, FIFO or socket (named directly or through a symlink) gets the
finished bytes, in order, once the writer succeeded; ``-`` (``STDOUT``) is standard output; a
symlink keeps pointing where it did and its target is replaced. Names are bounded
(``check_path_length``): a name past the file system's 255 bytes is one error naming the limit.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import logging
import os
import queue
import re
import secrets
import shutil
import stat
import sys
import tempfile
import threading
from collections.abc import Generator, Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from pipeline.errors import AdaptuneError, ConfigError, InputError, OutputError

T = TypeVar("T")
log = logging.getLogger(__name__)


TEMP_SUFFIX = ".tmp"
OLD_SUFFIX = ".old"  # atomic_dir: the previous folder, set aside during the swap
_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM)
STDOUT = "-"
"""The output path that is standard output (``--out -``): written through, as a FIFO is."""
SPOOL_NAME = "adaptune-out"
"""What an output written through is spooled in first: ``.adaptune-out.<pid>.<hex>.tmp`` in
the system's temporary folder (a device's folder, /dev, takes no files of ours)."""
NAME_MAX = 255
"""The longest name of a file or folder [bytes] (Linux file systems' NAME_MAX)."""
PATH_MAX = 4095
"""The longest path [bytes] the kernel takes (PATH_MAX, less its terminating NUL)."""
TEMP_NAME_EXTRA = 32
"""What a temporary's name adds to its output's: ``.``, ``.<pid>.<8 hex>.tmp`` and a
library's own suffix (DuckDB's ``.wal``), with room to spare."""
MAX_OUTPUT_NAME = NAME_MAX - TEMP_NAME_EXTRA
"""The longest name of an output file or folder [bytes]: 223, so that its temporary's fits."""


def check_path_length(path: str | os.PathLike[str], what: str, *, last_max: int = NAME_MAX,
                      error: type[AdaptuneError] = ConfigError) -> Path:
    """``path`` when the kernel can take it: at most ``PATH_MAX`` bytes, every name in it at
    most ``NAME_MAX`` (its last ``last_max``: ``MAX_OUTPUT_NAME`` for an output). ``error``
    naming ``what``, the name's length and the limit otherwise (the OSError "File name too
    long" of a stat would be a traceback)."""
    p = Path(path)
    size = len(os.fsencode(p))
    if size > PATH_MAX:
        raise error(f"{_shortened(p)}: the {what} is {size} bytes long, more than the "
                    f"{PATH_MAX} a path may have")
    parts = p.parts
    for k, part in enumerate(parts):
        limit = last_max if k == len(parts) - 1 else NAME_MAX
        size = len(os.fsencode(part))
        if size > limit:
            rule = (f"the {NAME_MAX} of a file name" if limit == NAME_MAX else
                    f"the {limit} an output's name may have (a file name's {NAME_MAX}, less "
                    f"{NAME_MAX - limit} for its temporary)")
            raise error(f"{_shortened(p)}: the {what} has a name of {size} bytes "
                        f"({_shortened(Path(part))}), more than {rule}")
    return p


def _shortened(path: Path, keep: int = 48) -> str:
    """``path`` as text, its middle elided past ``keep`` characters (a name of 300 bytes is
    named, not printed whole)."""
    text = str(path)
    return text if len(text) <= keep else f"{text[:keep // 2]}...{text[-keep // 2:]}"


def output_path(final: str | os.PathLike[str]) -> Path:
    """``final`` checked as a file to write: not empty, not a folder; its folder is created.

    Raises OutputError naming the path and the rule.
    """
    if not os.fspath(final).strip():
        raise OutputError("the output path is empty")
    path = check_path_length(final, "output path", last_max=MAX_OUTPUT_NAME, error=OutputError)
    if path.is_dir():
        raise OutputError(f"{path}: is a folder; the output must be a file path")
    _make_parent(path)
    return path


def output_folder(folder: str | os.PathLike[str], *, of: Path | None = None) -> Path:
    """``folder``, created with its parents when missing: the one place an output folder is
    made. OutputError naming the file in the way, or the reason (a read-only file system, no
    permission); with ``of`` (a file to write there) the error names that file."""
    if not os.fspath(folder).strip():
        raise OutputError("the output folder path is empty")
    path = check_path_length(folder, "output folder", error=OutputError)
    what = f"{of}: cannot create its folder" if of is not None else (
        f"{path}: cannot create the output folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        blocker = next((p for p in [path, *path.parents] if p.exists() and not p.is_dir()),
                       path)
        kind = _file_kind(blocker.stat().st_mode) if blocker.exists() else "a file"
        raise OutputError(f"{what}, {blocker} is {kind}") from None
    except OSError as exc:
        raise OutputError(f"{what} ({exc.strerror})") from None
    return path


def _make_parent(path: Path) -> None:
    """Create the folder of ``path``; OutputError naming the file in the way, or the reason."""
    output_folder(path.parent, of=path)


MAX_INPUT_BYTES = 64 << 20
"""The largest parameter, pose, times, calibration or index file read: 64 MiB (KITTI's
longest pose file is 0.5 MiB)."""


@contextlib.contextmanager
def open_input(path: str | os.PathLike[str], kind: str, *, hint: str = "",
               limit: int = MAX_INPUT_BYTES, error: type[AdaptuneError] = InputError,
               follow_links: bool = True) -> Iterator[tuple[Any, int]]:
    """``(binary file, size)`` of the regular file ``path`` (a ``kind``), open for the block:
    the checks of ``read_input`` done before any byte is read."""
    p = check_path_length(path, kind, error=error)
    try:
        st = os.stat(p) if follow_links else os.lstat(p)
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"{p}: no such {kind}{hint}") from None
    except OSError as exc:
        raise error(f"{p}: cannot read the {kind} ({exc.strerror})") from None
    _check_regular(p, st, kind, limit, error)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | (
        0 if follow_links else getattr(os, "O_NOFOLLOW", 0))
    try:
        fd = os.open(p, flags)
    except OSError as exc:
        raise error(f"{p}: cannot open the {kind} ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as fh:
        now = os.fstat(fd)
        if (now.st_ino, now.st_dev) != (st.st_ino, st.st_dev):
            raise error(f"{p}: changed while being opened")
        _check_regular(p, now, kind, limit, error)
        try:
            yield fh, now.st_size
        except OSError as exc:
            raise error(f"{p}: cannot read the {kind} ({exc.strerror})") from None


def read_input(path: str | os.PathLike[str], kind: str, *, hint: str = "",
               limit: int = MAX_INPUT_BYTES, error: type[AdaptuneError] = InputError,
               follow_links: bool = True) -> bytes:
    """The bytes of the regular file ``path`` (a ``kind``): the one bounded reader of the
    small files adaptune reads whole (parameter, pose, times, calibration, index, manifest).

    ``error`` (InputError by default) naming the file and the rule, at once and without
    blocking: missing (with ``hint``), a FIFO, a device, a folder, more than ``limit`` bytes
    (the limit named). Checked with stat, then opened with O_NONBLOCK and checked again on the
    open file (a FIFO swapped in between is not waited on); ``follow_links`` False refuses a
    symlink too (O_NOFOLLOW).
    """
    with open_input(path, kind, hint=hint, limit=limit, error=error,
                    follow_links=follow_links) as (fh, _):
        data: bytes = fh.read(limit + 1)
    if len(data) > limit:
        raise error(f"{path}: more than the {_bytes(limit)} a {kind} may hold")
    return data


def read_input_text(path: str | os.PathLike[str], kind: str, *,
                    error: type[AdaptuneError] = InputError, strict: bool = False,
                    hint: str = "") -> str:
    """``read_input`` decoded as UTF-8 (a byte-order mark dropped); undecodable bytes become
    U+FFFD, or with ``strict`` are ``error`` naming the file and the offset."""
    data = read_input(path, kind, error=error, hint=hint)
    try:
        return data.decode("utf-8-sig", errors="strict" if strict else "replace")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start})") from None


def _check_regular(path: Path, st: os.stat_result, kind: str, limit: int,
                   error: type[AdaptuneError]) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: is not a regular file (a {kind} must be one; this is "
                    f"{_file_kind(st.st_mode)})")
    if st.st_size > limit:
        raise error(f"{path}: {st.st_size} bytes, more than the {_bytes(limit)} a {kind} may "
                    "hold")


def _file_kind(mode: int) -> str:
    for test, name in ((stat.S_ISLNK, "a symlink"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a device"),
                       (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISREG, "a file")):
        if test(mode):
            return name
    return "not a file"


def _bytes(n: int) -> str:
    """``n`` bytes in the largest binary unit that divides it: 64 MiB, 16 GiB, 100 bytes."""
    for shift, unit in ((30, "GiB"), (20, "MiB"), (10, "KiB")):
        if n >= 1 << shift and n % (1 << shift) == 0:
            return f"{n >> shift} {unit}"
    return f"{n} bytes"


def input_file(path: str | os.PathLike[str], kind: str, hint: str = "") -> Path:
    """``path`` when it is a regular file (links followed); InputError naming it and ``kind``
    (with ``hint`` when it is missing) otherwise: a folder, FIFO or device is refused before a
    reader would block on it or misread it."""
    p = check_path_length(path, kind, error=InputError)
    try:
        st = p.stat()
    except (FileNotFoundError, NotADirectoryError):
        raise InputError(f"{p}: no such {kind}{hint}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {kind} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{p}: is not a regular file (a {kind} must be one; this is "
                         f"{_file_kind(st.st_mode)})")
    return p


PLAIN_NAME_MAX = 200
"""The longest name [bytes] that becomes files under an output folder: room for what is added
to it (``.mcap``, ``sequence=``, a temporary's 32) within a file name's 255."""
PLAIN_NAME_RULE = (f"a plain file name: not empty, at most {PLAIN_NAME_MAX} bytes, no '/', "
                   "'\\' or control characters, not starting with '.'")
"""What a name that becomes a file in an output folder must be (``check_plain_name``)."""


def check_plain_name(name: object, what: str, error: type[Exception] = ConfigError) -> str:
    """``name`` when it is a plain file name (``PLAIN_NAME_RULE``): the one path guard for
    names that become files or folders under an output folder (sequence names, split
    entries); ``error`` naming ``what`` and the rule otherwise (a name like ``../../x`` or
    ``a/b`` would write outside the folder, or record such a path)."""
    if (not isinstance(name, str) or not name or name.startswith(".")
            or len(name.encode("utf-8", "surrogatepass")) > PLAIN_NAME_MAX
            or any(c in name for c in "/\\") or any(ord(c) < 32 or ord(c) == 127 for c in name)):
        raise error(f"{what} must be {PLAIN_NAME_RULE}, got {name!r}")
    return name


def refuse_input_as_output(out: str | os.PathLike[str],
                           inputs: Iterable[str | os.PathLike[str] | None]) -> None:
    """OutputError when ``out`` is one of ``inputs`` (the same file, by any path to it), or
    a name too long to write (``check_path_length``). Standard output (``-``) is no input."""
    if os.fspath(out) == STDOUT:
        return
    out_path = check_path_length(out, "output path", last_max=MAX_OUTPUT_NAME,
                                 error=OutputError)
    for item in inputs:
        if item is None:
            continue
        inp = Path(item)
        try:
            same = (os.path.samefile(out_path, inp) if out_path.exists() and inp.exists()
                    else out_path.resolve() == inp.resolve())
        except OSError:  # an input that cannot be looked at is no file written here
            continue
        if same:
            raise OutputError(f"{out_path}: the output is also an input ({inp}); "
                              "write to another path")


def _temp_pattern(final: Path, suffix: str = TEMP_SUFFIX) -> re.Pattern[str]:
    """Names of the temporaries of ``final``: ``.<name>.<pid>.<8 hex><suffix>`` (this version)
    or ``.<name>.<8 chars>.tmp`` (mkstemp, earlier versions)."""
    legacy = "|[a-z0-9_]{8}" if suffix == TEMP_SUFFIX else ""
    return re.compile(rf"\.{re.escape(final.name)}\.(?:(\d+)\.[0-9a-f]{{8}}{legacy})"
                      rf"{re.escape(suffix)}(?:\.[a-z]+)?")  # + a library's own (DuckDB .wal)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_temps(final: str | os.PathLike[str]) -> list[Path]:
    """Remove what killed writers of ``final`` left beside it: temporaries whose process is
    gone (or of earlier versions, which did not record it). Returns the paths removed."""
    final = Path(final)
    try:
        candidates = sorted(final.parent.iterdir())
    except OSError:
        return []
    removed = []
    for suffix in (OLD_SUFFIX, TEMP_SUFFIX):
        pattern = _temp_pattern(final, suffix)
        for p in candidates:
            m = pattern.fullmatch(p.name)
            if m is None or (m.group(1) is not None and _alive(int(m.group(1)))):
                continue
            with contextlib.suppress(OSError):
                if suffix == OLD_SUFFIX and not final.exists():
                    os.replace(p, final)  # killed between the two renames of atomic_dir
                    continue
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
                removed.append(p)
    if removed:
        log.info("%s: removed %d temporary file(s) of an interrupted earlier write",
                 final, len(removed))
    return removed


def _temp_beside(final: Path, suffix: str = TEMP_SUFFIX) -> Path:
    return final.with_name(f".{final.name}.{os.getpid()}.{secrets.token_hex(4)}{suffix}")


@contextlib.contextmanager
def _as_output_error(final: Path, tmp: Path) -> Iterator[None]:
    """OSErrors of writing ``tmp`` (or of the disk) -> OutputError naming ``final``."""
    try:
        yield
    except OSError as exc:
        names = {os.fspath(tmp), str(tmp)}
        if getattr(exc, "filename", None) in names or exc.errno in _WRITE_ERRNOS:
            raise OutputError(f"{final}: cannot write ({exc.strerror or exc})") from None
        raise


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``final``; rename it onto ``final`` on success.

    On any exception the temporary file is removed and ``final`` is left byte-identical.
    The file is created with the umask's permissions (as ``open`` would). Temporaries that a
    killed writer of ``final`` left are removed first. OSErrors of the output (no permission,
    a folder or a file in the way, disk full) become one OutputError naming ``final``.

    ``final`` a symlink: its target is replaced, the link stays. ``final`` a character device,
    FIFO or socket (through symlinks too), or ``STDOUT``: the finished file's bytes are written
    through to it, in order, and it is never replaced (``written_through``); a block device is
    refused.
    """
    if os.fspath(final) == STDOUT:
        with written_through(STDOUT) as tmp:
            yield tmp
        return
    final = output_path(final)
    if through_kind(final) is not None:  # stat follows every link (/dev/stdout's too)
        with written_through(final) as tmp:
            yield tmp
        return
    target = link_target(final)
    remove_stale_temps(target)
    tmp = _temp_beside(target)
    try:
        with _as_output_error(final, tmp):
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))  # umask applies
        with _as_output_error(final, tmp):
            yield tmp
        with _as_output_error(final, tmp):
            os.replace(tmp, target)
    except BaseException:
        _remove_temp(tmp)
        raise


def _remove_temp(tmp: Path) -> None:
    """Remove the temporary file ``tmp`` and what a library put beside it (DuckDB's .wal)."""
    for p in [tmp, *tmp.parent.glob(glob.escape(tmp.name) + ".*")]:
        with contextlib.suppress(OSError):
            p.unlink()


def link_target(path: Path) -> Path:
    """What the symlink ``path`` points to, its own links resolved (its folder made when
    missing, as an output's is); ``path`` itself when it is no symlink. An output written
    there replaces the target and leaves the link as it is."""
    if not path.is_symlink():
        return path
    target = Path(os.path.realpath(path))
    _make_parent(target)
    return target


def through_kind(path: Path) -> str | None:
    """"a FIFO", "a device" or "a socket" when ``path`` (links followed) is an output to write
    through rather than replace; None for a regular file, a folder or nothing. OutputError for
    a block device (a disk is no output of adaptune's)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISBLK(mode):
        raise OutputError(f"{path}: is a block device; adaptune writes no disk (give a file "
                          "path, a FIFO, a character device or -)")
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
        return _file_kind(mode)
    return None


COPY_CHUNK = 1 << 20
"""The bytes an output written through is copied in at a time."""


@contextlib.contextmanager
def written_through(target: Path | str) -> Iterator[Path]:
    """Yield a temporary file (``SPOOL_NAME``, private to the user); once the block succeeded,
    write its bytes to ``target`` (a character device, FIFO or socket; ``STDOUT``), in order,
    then remove it. On an exception nothing is written to ``target``. A FIFO with no reader is
    waited on, as a shell's ``>`` waits (said once on the log). OutputError naming ``target``
    when it takes no more (a closed pipe, a full device, a socket nobody listens on)."""
    name = "stdout" if target == STDOUT else str(target)
    spool = Path(tempfile.gettempdir()) / SPOOL_NAME
    remove_stale_temps(spool)
    tmp = _temp_beside(spool)
    try:
        with _as_output_error(Path(name), tmp):
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            yield tmp
        try:
            with open(tmp, "rb") as src:
                _copy_through(src, target)
        except OSError as exc:
            raise OutputError(f"{name}: cannot write the output "
                              f"({exc.strerror or exc})") from None
    finally:
        _remove_temp(tmp)


def _copy_through(src: Any, target: Path | str) -> None:
    """Every byte of the open file ``src`` to ``target`` (``written_through``)."""
    if target == STDOUT:
        _copy_to_stdout(src)
        return
    if stat.S_ISSOCK(os.stat(target).st_mode):
        import socket

        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.connect(os.fspath(target))
            sock.sendfile(src)
        return
    flags = os.O_WRONLY | os.O_NOCTTY
    try:
        fd = os.open(target, flags | os.O_NONBLOCK)  # a FIFO with no reader: ENXIO, at once
        os.set_blocking(fd, True)
    except OSError as exc:
        if exc.errno != errno.ENXIO:
            raise
        log.warning("%s: a FIFO no process reads yet; waiting for one", target)
        fd = os.open(target, flags)
    try:
        _copy_to_fd(src, fd)
    finally:
        os.close(fd)


def _copy_to_fd(src: Any, fd: int) -> None:
    while chunk := src.read(COPY_CHUNK):
        view = memoryview(chunk)
        while view:
            view = view[os.write(fd, view):]


def _copy_to_stdout(src: Any) -> None:
    """``src`` to standard output: straight to its file descriptor (nothing is left in
    Python's buffer when the reader is gone), or to ``sys.stdout.buffer`` when it has none
    (a test runner's)."""
    import io

    sys.stdout.flush()
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, io.UnsupportedOperation):
        while chunk := src.read(COPY_CHUNK):
            sys.stdout.buffer.write(chunk)
        sys.stdout.buffer.flush()
        return
    _copy_to_fd(src, fd)


@contextlib.contextmanager
def atomic_dir(final: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary folder beside ``final``; on success it replaces ``final``.

    On any exception the temporary folder is removed and ``final`` is left untouched. The
    swap is two renames (the old folder aside, the new one in; the old one back if the second
    fails), then the old one is deleted. Permissions and stale temporaries as ``atomic_path``.
    """
    if not os.fspath(final).strip():
        raise OutputError("the output path is empty")
    final = check_path_length(final, "output folder", last_max=MAX_OUTPUT_NAME,
                              error=OutputError)
    if final.exists() and not final.is_dir():
        raise OutputError(f"{final}: is {_file_kind(final.stat().st_mode)}; the output must be "
                          "a folder")
    _make_parent(final)
    final = link_target(final)  # a symlink to a folder: the folder is replaced, the link stays
    remove_stale_temps(final)
    tmp = _temp_beside(final)
    try:
        with _as_output_error(final, tmp):
            tmp.mkdir(0o777)  # umask applies
        with _as_output_error(final, tmp):
            yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    with _as_output_error(final, tmp):
        try:
            if final.exists():
                old = _temp_beside(final, OLD_SUFFIX)
                os.replace(final, old)
            os.replace(tmp, final)
        except BaseException:
            if old is not None and not final.exists():
                os.replace(old, final)
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def exclusive_folder(folder: str | os.PathLike[str], what: str = "another process"
                     ) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (made if missing) while the block runs.

    ``fcntl.flock`` on the folder itself (no lock file is left in it); the lock goes with the
    process however it ends. Raises ConfigError at once when another process holds it.
    """
    import fcntl

    from pipeline.errors import ConfigError

    path = output_folder(folder)
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(f"{path}: {what} is writing there (the folder is locked); wait "
                              "for it to end or use another output folder") from None
        yield path
    finally:
        os.close(fd)


def atomic_write_text(final: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``final`` atomically."""
    with atomic_path(final) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_bytes(final: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``final`` atomically."""
    with atomic_path(final) as tmp:
        tmp.write_bytes(data)


def prefetch(items: Iterable[T], depth: int = 4) -> Generator[T, None, None]:
    """``items``, produced by a background thread up to ``depth`` ahead of the consumer.

    Reading and decoding a sequence (file reads, zstd, copies: all release the GIL) then
    overlap the odometry that consumes it. An exception in the producer is raised in the
    consumer at the same point; a consumer that stops early stops the producer.
    """
    buffer: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(message: tuple[str, Any]) -> bool:
        """Queue ``message`` unless the consumer has stopped; False when it has."""
        while not stop.is_set():
            with contextlib.suppress(queue.Full):
                buffer.put(message, timeout=0.05)
                return True
        return False

    def produce() -> None:
        try:
            for item in items:
                if not put(("item", item)):
                    return
            put(("end", None))
        except BaseException as exc:  # handed to the consumer
            put(("error", exc))

    thread = threading.Thread(target=produce, name="prefetch", daemon=True)
    thread.start()
    try:
        while True:
            kind, value = buffer.get()
            if kind == "end":
                return
            if kind == "error":
                raise value
            yield value
    finally:
        stop.set()
        thread.join()
