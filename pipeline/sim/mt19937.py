"""The Mersenne Twister of numba's ``np.random`` (MT19937, ``np.random.seed(seed)`` and
``np.random.random()``), to the bit, as numba code the compiler inlines (docs/simulator.md,
"Speed").

Why: numba's own generator costs ~10 ns a number (a call into its C helpers and the state of the
thread looked up every time); this one fills doubles in blocks, ~4x faster read from the block,
and a scan's returns draw 250-700 thousand of them in the one sequential part of the sensor
model (``pipeline.sim.returns_kernel.draw_uniforms``). The stream is numba's, so the scans are
what they were with ``np.random`` (tests/sim/test_sim_kernels.py).

A stream is three arrays: ``mt`` (624,) uint32 state, ``buf`` (312,) float64 doubles drawn,
``pos`` (1,) int64 the next one in ``buf``.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

N, M = 624, 397
"""MT19937's state size and shift (Matsumoto & Nishimura 1998)."""
U32 = NDArray[np.uint32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@numba.njit(cache=True, nogil=True)
def seeded(seed: int) -> tuple[U32, F64, I64]:  # pragma: no cover - compiled
    """A stream at ``np.random.seed(seed)`` (Knuth's initialisation of the reference code,
    seed taken modulo 2^32)."""
    mt = np.empty(N, np.uint32)
    s = np.uint64(seed) & np.uint64(0xFFFFFFFF)
    for pos in range(N):
        mt[pos] = np.uint32(s)
        s = (np.uint64(1812433253) * (s ^ (s >> np.uint64(30))) + np.uint64(pos + 1)
             ) & np.uint64(0xFFFFFFFF)
    return mt, np.empty(N // 2), np.full(1, N // 2, np.int64)


@numba.njit(cache=True, nogil=True)
def fill(mt: U32, buf: F64, pos: I64, out: F64) -> None:  # pragma: no cover - compiled
    """``out`` (K,): the stream's next K doubles in [0, 1) (53 bits, numba's and numpy's
    ``random()``)."""
    for i in range(len(out)):
        if pos[0] == N // 2:
            _refill(mt, buf)
            pos[0] = 0
        out[i] = buf[pos[0]]
        pos[0] += 1


@numba.njit(cache=True, nogil=True, inline="always")
def _mix(a: np.uint32, b: np.uint32, c: np.uint32) -> np.uint32:  # pragma: no cover
    y = (a & np.uint32(0x80000000)) | (b & np.uint32(0x7FFFFFFF))
    return np.uint32(c ^ (y >> np.uint32(1)) ^ (np.uint32(0x9908B0DF) * (y & np.uint32(1))))


@numba.njit(cache=True, nogil=True, inline="always")
def _temper(y: np.uint32) -> np.uint32:  # pragma: no cover - compiled
    y ^= y >> np.uint32(11)
    y ^= (y << np.uint32(7)) & np.uint32(0x9D2C5680)
    y ^= (y << np.uint32(15)) & np.uint32(0xEFC60000)
    return np.uint32(y ^ (y >> np.uint32(18)))


@numba.njit(cache=True, nogil=True)
def _refill(mt: U32, buf: F64) -> None:  # pragma: no cover - compiled
    """Twist the state and turn its 624 words into 312 doubles, (a >> 5, b >> 6) / 2^53."""
    for k in range(N - M):
        mt[k] = _mix(mt[k], mt[k + 1], mt[k + M])
    for k in range(N - M, N - 1):
        mt[k] = _mix(mt[k], mt[k + 1], mt[k + M - N])
    mt[N - 1] = _mix(mt[N - 1], mt[0], mt[M - 1])
    for i in range(N // 2):
        a = _temper(mt[2 * i]) >> np.uint32(5)
        b = _temper(mt[2 * i + 1]) >> np.uint32(6)
        buf[i] = (np.float64(b) + np.float64(a) * 67108864.0) / 9007199254740992.0
