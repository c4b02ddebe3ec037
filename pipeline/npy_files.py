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


NPY_HEADER_MAX = 10 + (1 << 16)
"""Bytes that hold any .npy preamble and header numpy writes (format 1.0: a 2-byte length)."""


def npy_declaration(arr: NDArray[Any]) -> dict[str, Any]:
    """What a manifest records of an array it lists: ``{"shape": [...], "dtype": "<f8"}``."""
    return {"shape": [int(n) for n in arr.shape], "dtype": np.ascontiguousarray(arr).dtype.str}


def read_npy_file(path: Path, declared: Any, limit: int) -> bytes:
    """The bytes of the .npy file ``path`` once its header gives the shape and dtype the
    manifest ``declared`` ({"shape", "dtype"}) and its size is exactly that header's plus the
    array's bytes; all checked before the array's bytes are read (a file of gigabytes the
    manifest does not account for is refused at its size). ArtifactError otherwise."""
    import io

    from pipeline.io_utils import open_input

    if not (isinstance(declared, dict) and isinstance(declared.get("shape"), list)
            and all(isinstance(n, int) and not isinstance(n, bool) and n >= 0
                    for n in declared["shape"]) and isinstance(declared.get("dtype"), str)):
        raise ArtifactError(f"{path}: manifest.json declares no shape and dtype for it, got "
                            f"{declared!r}")
    shape, dtype = tuple(declared["shape"]), declared["dtype"]
    with open_input(path, "model file", hint=" (listed in manifest.json)", limit=limit,
                    error=ArtifactError, follow_links=False) as (fh, size):
        head = fh.read(min(size, NPY_HEADER_MAX))
        fp = io.BytesIO(head)
        got_shape, _, got_dtype = _header(fp, path)
        if tuple(got_shape) != shape or got_dtype.str != dtype:
            raise ArtifactError(f"{path}: holds shape {tuple(got_shape)} {got_dtype.str}, "
                                f"manifest.json declares {shape} {dtype}")
        count = 1
        for n in shape:
            count *= n
        expected = fp.tell() + count * got_dtype.itemsize
        if size != expected:
            raise ArtifactError(f"{path}: {size} bytes, its declared shape {shape} {dtype} "
                                f"takes {expected}")
        data = head + fh.read(expected - len(head) + 1)
    if len(data) != expected:
        raise ArtifactError(f"{path}: changed while being read")
    return data


def _header(fp: Any, what: str | Path) -> tuple[tuple[int, ...], bool, np.dtype[Any]]:
    """(shape, fortran order, dtype) of the .npy header at ``fp``; ArtifactError unless it is
    one of plain numbers (bool, integer, float)."""
    import tokenize

    fmt = np.lib.format
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
    return tuple(int(n) for n in shape), bool(fortran), dtype


def parse_npy(data: bytes, what: str | Path) -> NDArray[Any]:
    """The array of an .npy file's bytes, allow_pickle=False in spirit: bool, integer or float
    only, and the header's shape must account for exactly the bytes that follow it (checked
    before anything is allocated). ArtifactError otherwise."""
    import io

    fp = io.BytesIO(data)
    shape, fortran, dtype = _header(fp, what)
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


