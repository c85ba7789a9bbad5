"""The fitter's random draws from a counter-based generator (numpy side).

A fit's random numbers (the Latin-hypercube screening, the jitter of the random starts,
the basin hops) are ``splitmix64`` hashes of (seed, stream, index) (Steele, Lea and
Flood 2014, the finaliser of Java's SplittableRandom), not the draws of a
``numpy.random.Generator``. A counter-based generator has no state: the compiled kernel
(:mod:`.draws_kernel`, which has the same functions compiled) draws the very same
numbers inside its one call from the seed alone, so a fit pays no generator set-up in
Python, and the numpy reference implementation, which uses these functions, searches from
the same candidates. Uniforms are bit for bit the same on both sides; normals (Box and
Muller 1958) agree to the last unit or two of the library's ``log`` and ``cos``.

Streams: :data:`STREAM_STRATA` and :data:`STREAM_OFFSETS` (the Latin hypercube),
:data:`STREAM_JITTER` (random starts), :data:`STREAM_HOPS` (basin hops).
"""

from __future__ import annotations

import numpy as np

STREAM_STRATA, STREAM_OFFSETS, STREAM_JITTER, STREAM_HOPS = 0, 1, 2, 3
GOLDEN = 0x9E3779B97F4A7C15
_M1 = 0xBF58476D1CE4E5B9
_M2 = 0x94D049BB133111EB
_MASK = (1 << 64) - 1


def _mix_int(x: int) -> int:
    """splitmix64's finaliser on a Python int (mod 2^64)."""
    x &= _MASK
    x = ((x ^ (x >> 30)) * _M1) & _MASK
    x = ((x ^ (x >> 27)) * _M2) & _MASK
    return x ^ (x >> 31)


def seed_key(seed: int) -> int:
    """The generator's key of a seed (an integer >= 0 of any size): its 64-bit words
    hashed in turn, the top bit dropped (the kernel takes it as a signed 64-bit integer)."""
    s = int(seed)
    key = GOLDEN
    while True:  # every word shifts the state by GOLDEN first: no seed maps to another's key
        key = _mix_int((key ^ (s & _MASK)) + GOLDEN)
        s >>= 64
        if not s:
            return key >> 1


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser on an array of uint64 (arrays wrap silently)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(_M1)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(_M2)
    return x ^ (x >> np.uint64(31))


def uniforms(key: int, stream: int, count: int) -> np.ndarray:
    """``count`` uniforms in (0, 1) of ``stream`` (indices 0 .. count - 1)."""
    base = _mix(np.array([(key + GOLDEN * (stream + 1)) & _MASK], np.uint64))
    index = np.arange(1, count + 1, dtype=np.uint64) * np.uint64(GOLDEN)
    h = _mix(base + index)
    return ((h >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0**-53


def normals(key: int, stream: int, count: int) -> np.ndarray:
    """``count`` standard normals of ``stream`` (Box-Muller, one from each pair of
    uniforms 2i, 2i + 1)."""
    u = uniforms(key, stream, 2 * count)
    return np.sqrt(-2.0 * np.log(u[0::2])) * np.cos(2.0 * np.pi * u[1::2])


def latin_hypercube(key: int, n: int, lo, hi) -> np.ndarray:
    """``n`` points of a Latin hypercube in the box (lo, hi) (McKay, Beckman and Conover
    1979): every coordinate's range cut into ``n`` strata, the strata permuted (by the
    stable order of ``n`` uniforms of :data:`STREAM_STRATA`) and each sampled at a uniform
    offset (:data:`STREAM_OFFSETS`). Coordinate ``q`` uses indices ``q n .. q n + n - 1``."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    p = lo.size
    keys = uniforms(key, STREAM_STRATA, n * p).reshape(p, n)
    strata = np.argsort(keys, axis=1, kind="stable").T
    offsets = uniforms(key, STREAM_OFFSETS, n * p).reshape(p, n).T
    return lo + (strata + offsets) / n * (hi - lo)
