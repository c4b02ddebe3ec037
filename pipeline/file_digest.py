"""SHA-256 of files and folders, remembered in the user cache (``~/.cache/adaptune/digests``)
by path, size and modification time, so that a resumed study does not hash gigabytes of
sequences again. The remembered state never enters an output: an output holds the digest
alone, the same for the same bytes wherever and whenever they were written
(docs/design.md, "Same numbers on every machine")."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

from pipeline import user_cache_dir

CHUNK = 1 << 20


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes; from the cache when its size and modification time
    are those it had when it was hashed."""
    path = Path(path)
    st = path.stat()
    key = [st.st_size, st.st_mtime_ns, st.st_ino]
    entry = _entry(path)
    with contextlib.suppress(OSError, ValueError, TypeError):
        known = json.loads(entry.read_text(encoding="utf-8"))
        if known["key"] == key and isinstance(known["sha256"], str):
            return known["sha256"]
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(CHUNK):
            digest.update(block)
    value = digest.hexdigest()
    _remember(entry, {"key": key, "sha256": value})
    return value


def sha256_tree(path: str | os.PathLike[str]) -> str | None:
    """SHA-256 of a file, or of a folder (its files' relative paths and SHA-256s in sorted
    order); None when ``path`` is neither."""
    path = Path(path)
    if path.is_file():
        return sha256_file(path)
    if not path.is_dir():
        return None
    digest = hashlib.sha256()
    for f in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(f"{f.relative_to(path).as_posix()}\0{sha256_file(f)}\n".encode())
    return digest.hexdigest()


def _entry(path: Path) -> Path:
    name = hashlib.sha1(str(path.resolve()).encode(), usedforsecurity=False).hexdigest()
    return user_cache_dir() / "digests" / f"{name}.json"


def _remember(entry: Path, value: dict[str, object]) -> None:
    """Best effort: a cache that cannot be written only costs the hashing next time."""
    from pipeline.io_utils import atomic_write_text

    with contextlib.suppress(OSError, Exception):
        entry.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(entry, json.dumps(value))
