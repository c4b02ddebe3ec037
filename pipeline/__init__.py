"""adaptune's library: everything but the command line (stages/).

Importing it points numba's on-disk cache of compiled kernels (``@numba.njit(cache=True)``) at a
user cache folder, ``$XDG_CACHE_HOME/adaptune/numba`` (``~/.cache/adaptune/numba``), unless
``NUMBA_CACHE_DIR`` is set: by default numba writes beside the module, into the installed
package, which fails on a read-only install. numba reads the variable when
it is first imported, and every module of this package that uses numba imports it after this.
"""

from __future__ import annotations

import os
from pathlib import Path


def user_cache_dir() -> Path:
    """adaptune's cache folder: ``$XDG_CACHE_HOME/adaptune`` or ``~/.cache/adaptune``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "adaptune"


os.environ.setdefault("NUMBA_CACHE_DIR", str(user_cache_dir() / "numba"))
