"""Plain numpy arrays on disk, safely: ``.npy`` files written without pickle (with their sha256),
and read only from regular files whose header accounts for every byte (docs/design.md,
"Contracts"). The artifact and the PCA folder are made of them.

numpy and the standard library only: the deployable runtime imports it.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ArtifactError

MAX_ARRAY_BYTES = 16 << 30
"""The largest array file read (16 GiB)."""


def save_npy(path: Path, arr: NDArray[Any]) -> str:
    """np.save without pickle; returns the sha256 of the written file."""
    np.save(path, np.ascontiguousarray(arr), allow_pickle=False)
    return hashlib.sha256(path.read_bytes()).hexdigest()



def read_regular_file(path: Path, limit: int) -> bytes:
    """The bytes of ``path`` if it is a regular file (not a symlink, FIFO, device or folder) of
    at most ``limit`` bytes; ArtifactError otherwise. Checked with lstat before opening, opened
    without following links and without blocking, and checked again on the open file."""
    import os
    import stat

    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise ArtifactError(f"{path}: missing (listed in manifest.json)") from None
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot read ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise ArtifactError(f"{path}: not a regular file ({_file_kind(st.st_mode)})")
    if st.st_size > limit:
        raise ArtifactError(f"{path}: {st.st_size} bytes, more than the {limit} allowed")
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise ArtifactError(f"{path}: cannot open ({exc.strerror})") from None
    with os.fdopen(fd, "rb") as fh:
        now = os.fstat(fh.fileno())
        if (now.st_ino, now.st_dev) != (st.st_ino, st.st_dev) or not stat.S_ISREG(now.st_mode):
            raise ArtifactError(f"{path}: changed while being opened")
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise ArtifactError(f"{path}: more than the {limit} bytes allowed")
    return data


def _file_kind(mode: int) -> str:
    import stat

    for test, name in ((stat.S_ISLNK, "a symlink"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a device"),
                       (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a file"


def parse_npy(data: bytes, what: str | Path) -> NDArray[Any]:
    """The array of an .npy file's bytes, allow_pickle=False in spirit: bool, integer or float
    only, and the header's shape must account for exactly the bytes that follow it (checked
    before anything is allocated). ArtifactError otherwise."""
    import io
    import tokenize

    fmt = np.lib.format
    fp = io.BytesIO(data)
    try:
        version = fmt.read_magic(fp)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fp)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(fp)
        else:
            raise ValueError(f"npy format version {version}")
    except (ValueError, SyntaxError, TypeError, tokenize.TokenError) as exc:  # a bad header
        raise ArtifactError(f"{what}: not a plain numpy array ({exc})") from None
    if dtype.hasobject or dtype.kind not in "biuf" or dtype.subdtype is not None:
        raise ArtifactError(f"{what}: dtype {dtype} is not a plain number type")
    count = 1
    for n in shape:
        count *= int(n)
    body = len(data) - fp.tell()
    if count * dtype.itemsize != body:
        raise ArtifactError(f"{what}: the header claims shape {tuple(shape)} "
                            f"({count * dtype.itemsize} bytes), the file holds {body}")
    arr = np.frombuffer(data, dtype, count, offset=fp.tell())
    return np.array(arr.reshape(shape, order="F" if fortran else "C"),
                    dtype=dtype.newbyteorder("="), order="C")


