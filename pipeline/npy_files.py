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
    at most ``limit`` bytes; ArtifactError otherwise (``pipeline.io_utils.read_input``: checked
    before opening, opened without following links and without blocking, checked again)."""
    from pipeline.io_utils import read_input

    return read_input(path, "model file", hint=" (listed in manifest.json)", limit=limit,
                      error=ArtifactError, follow_links=False)


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


