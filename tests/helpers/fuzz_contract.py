"""The contract every fuzz target asserts (issue 13, "How to make it stay fixed").

On any input a reader, a parser or a command ends in one of two ways:
- it refuses: an AdaptuneError whose message is one non-empty line (the library), or exit code 1
  with one ``adaptune: error: ...`` line on stderr (the CLI); or
- it succeeds, and the target checks that its output is valid.
Never another exception (a traceback), never a hang (``HANG_S`` seconds an example), never a
changed input file (sha256 of every input before and after).

Size: each target has a small fixed example count, derandomized, for ``make test``.
``ADAPTUNE_FUZZ_EXAMPLES=N`` (``make fuzz``) runs N examples a target with random seeds; a
failure prints the ``@reproduce_failure`` blob that replays it.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from hypothesis import HealthCheck, event, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from pipeline.errors import AdaptuneError
from pipeline.stamps import MAX_STAMP_S

T = TypeVar("T")
HANG_S = 20.0
"""An example that takes longer is a hang (the slowest one takes well under a second)."""
FUZZ_EXAMPLES_ENV = "ADAPTUNE_FUZZ_EXAMPLES"


def fuzz(examples: int) -> Callable[[T], T]:
    """Hypothesis settings of a target: ``examples`` derandomized examples, or the count of
    ADAPTUNE_FUZZ_EXAMPLES with random seeds (``make fuzz``)."""
    n = int(os.environ.get(FUZZ_EXAMPLES_ENV, "0") or 0)
    return settings(  # type: ignore[return-value]
        max_examples=n or examples,
        derandomize=not n,
        deadline=None,
        database=None,
        print_blob=True,
        suppress_health_check=list(HealthCheck),
    )


class Hang(Exception):  # noqa: N818 - the name is what a failure report says
    """An example outlived HANG_S."""


@contextlib.contextmanager
def no_hang(seconds: float = HANG_S) -> Iterator[None]:
    """Raise Hang in the main thread after ``seconds`` (SIGALRM: also interrupts a blocking
    open() of a FIFO or a read)."""

    def on_alarm(signum: int, frame: Any) -> None:
        raise Hang(f"no answer after {seconds} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def digest(paths: Iterable[Path]) -> dict[Path, str]:
    """sha256 of every file under ``paths`` (files, or folders walked)."""
    out: dict[Path, str] = {}
    for path in paths:
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for f in files:
            if f.is_file():
                out[f] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def holds(call: Callable[[], T], inputs: Iterable[Path] = ()) -> T | None:
    """Run ``call`` under the library contract: its result, or None when it refused with an
    AdaptuneError of one line. Any other exception, a hang or a changed input fails."""
    inputs = list(inputs)
    before = digest(inputs)
    try:
        with no_hang():
            result = call()
    except AdaptuneError as exc:
        message = str(exc)
        assert message.strip() and "\n" not in message, f"not one line: {message!r}"
        result = None
    assert digest(inputs) == before, "an input file changed"
    event("refused" if result is None else "accepted")
    return result


@contextlib.contextmanager
def scratch(base: Path) -> Iterator[Path]:
    """A fresh folder under ``base`` for one example (hypothesis reuses function fixtures)."""
    with tempfile.TemporaryDirectory(dir=base) as name:
        yield Path(name)


# ----------------------------------------------------------------------------- strategies

RARELY = st.integers(0, 6).map(lambda v: v == 3)
"""True about once in 7 draws (hypothesis favours the ends of a range, so not ``== 0``)."""

NUMBER_TOKENS = st.one_of(
    st.integers(-(2**70), 2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["0", "1", "-1", "1e308", "1e-320", "2147483648", "nan", "inf", "-0",
                     "0x10", "1_000", "+", ".", "1e", "9" * 40]),
)
TOKENS = st.one_of(
    NUMBER_TOKENS,
    st.sampled_from(["#", "%", "//", ",", "Tr:", "Tr_velo_to_cam:", "P0:", "x", "FIELDS"]),
    st.text(st.characters(codec="utf-8"), max_size=6),
)


def text_lines(tokens: st.SearchStrategy[str] = TOKENS, width: int = 14,
               lines: int = 8) -> st.SearchStrategy[str]:
    """Text files of up to ``lines`` lines of up to ``width`` tokens (numbers mostly)."""
    line = st.lists(tokens, max_size=width).map(" ".join)
    return st.lists(line, max_size=lines).map("\n".join)


def mutate(data: bytes) -> st.SearchStrategy[bytes]:
    """``data`` with a few bytes flipped, cut short, or with bytes inserted."""

    @st.composite
    def draw(d: st.DrawFn) -> bytes:
        buf = bytearray(data)
        for _ in range(d(st.integers(1, 4))):
            if not buf:
                break
            kind = d(st.sampled_from(["flip", "cut", "insert", "zero"]))
            at = d(st.integers(0, len(buf) - 1))
            if kind == "flip":
                buf[at] ^= d(st.integers(1, 255))
            elif kind == "cut":
                del buf[at:]
            elif kind == "insert":
                buf[at:at] = d(st.binary(min_size=1, max_size=16))
            else:
                buf[at : at + 8] = bytes(len(buf[at : at + 8]))
        return bytes(buf)

    return draw()


def is_pose(T: NDArray[np.float64], tol: float = 2e-2) -> bool:
    """(..., 4, 4) finite rigid transforms."""
    R = T[..., :3, :3]
    eye = np.broadcast_to(np.eye(3), R.shape)
    return bool(np.isfinite(T).all() and np.allclose(T[..., 3, :], [0, 0, 0, 1])
                and np.allclose(np.swapaxes(R, -1, -2) @ R, eye, atol=tol)
                and (np.linalg.det(R) > 0).all())


def valid_stamps(stamps_ns: NDArray[np.int64]) -> bool:
    return bool(stamps_ns.dtype == np.int64 and np.all(np.diff(stamps_ns) > 0)
                and (stamps_ns >= 0).all() and (stamps_ns < MAX_STAMP_S * 10**9).all())
