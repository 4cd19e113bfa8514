"""The self-collision broad and narrow phase of :class:`~.proxies.ProxyModel` in machine code.

A scan of Talos' sphere proxies (``ActiveSet.scan``: the sphere pairs of each candidate pair
of joints closer than a slack, and the 16 closest of each) took 1.2-2.8 ms in numpy, most
of it in the overhead of small array operations over a few hundred pairs of sphere groups;
a near-body reach scans three times a call. The same search in C (every candidate joint pair,
its pairs of groups whose bounding spheres are within the slack, their sphere pairs within
it; for the closest, each joint pair's pairs sorted by distance, ties in the order found)
gives the same pairs in the same order as the numpy search, which stays the reference and
the path without a C compiler.

The library is compiled once per machine (``-O2``, 0.2 s) into ``$POSTUREGEN_CACHE/kernels``
(else ``~/.cache/posturegen/kernels``), keyed by its source's digest and the machine; a
process loads it in microseconds.
"""

from __future__ import annotations

import ctypes
import functools
import os
from pathlib import Path

import numpy as np

from .._compiler import kernel_library, kernel_path
from ..errors import PosturegenError

_SOURCE = r"""
#include <math.h>

typedef struct { double d; long i, j; } hit;

static double gap3(const double* a, const double* b) {
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* best[0..*count) sorted by distance, at most keep: (d, i, j) inserted after the equal ones
   (the earlier found first, as a stable sort), dropped when not among the keep closest. */
static void insert(hit* best, long* count, long keep, double d, long i, long j) {
    long at = *count;
    if (at == keep) {
        if (!(d < best[keep - 1].d)) return;
        --at;
    } else {
        ++*count;
    }
    while (at > 0 && best[at - 1].d > d) { best[at] = best[at - 1]; --at; }
    best[at].d = d; best[at].i = i; best[at].j = j;
}

/* The sphere pairs of the joint pairs links[0..nlinks) closer than slack[link]: each joint
   pair whose joints' bounding spheres (jc, jr by joint id) are within it, its group pairs
   (gp_start[k]..gp_start[k+1] of ga, gb) whose bounding spheres (gc, gr) are within it, and
   their spheres (gstart[g]..gstart[g+1]) within it, in that order. With keep > 0, only the
   keep closest of each joint pair, sorted by distance (ties in the order found; once keep
   are found, the bound is the farthest of them). Writes at most cap pairs; returns how many
   there are. */
long close_pairs(const double* c, const double* r, const double* gc, const double* gr,
                 const double* jc, const double* jr, const long* jp, const long* gp_start,
                 const long* ga, const long* gb, const long* gstart, const long* links,
                 long nlinks, const double* slack, long keep, hit* best,
                 long* oi, long* oj, long* olink, double* od, long cap) {
    long n = 0;
    for (long q = 0; q < nlinks; ++q) {
        long k = links[q];
        long a = jp[2 * k], b = jp[2 * k + 1];
        double s = slack[k];
        if (gap3(jc + 3 * a, jc + 3 * b) - jr[a] - jr[b] >= s) continue;
        long count = 0;
        for (long p = gp_start[k]; p < gp_start[k + 1]; ++p) {
            long A = ga[p], B = gb[p];
            if (gap3(gc + 3 * A, gc + 3 * B) - gr[A] - gr[B] >= s) continue;
            for (long i = gstart[A]; i < gstart[A + 1]; ++i) {
                if (gap3(c + 3 * i, gc + 3 * B) - r[i] - gr[B] >= s) continue;
                for (long j = gstart[B]; j < gstart[B + 1]; ++j) {
                    if (gap3(c + 3 * j, gc + 3 * A) - r[j] - gr[A] >= s) continue;
                    double d = gap3(c + 3 * i, c + 3 * j) - r[i] - r[j];
                    if (d >= s) continue;
                    if (keep > 0) {
                        insert(best, &count, keep, d, i, j);
                        if (count == keep && best[keep - 1].d < s) s = best[keep - 1].d;
                        continue;
                    }
                    if (n < cap) { oi[n] = i; oj[n] = j; olink[n] = k; od[n] = d; }
                    ++n;
                }
            }
        }
        for (long t = 0; t < count; ++t, ++n) {
            if (n < cap) { oi[n] = best[t].i; oj[n] = best[t].j; olink[n] = k; od[n] = best[t].d; }
        }
    }
    return n;
}
"""

_LONG = ctypes.c_long
_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
_LONG_P = ctypes.POINTER(_LONG)
_HIT_BYTES = 24  # sizeof(hit) on LP64


def _library_path() -> Path:
    """Where this machine's library is kept: its source's and the machine's digest."""
    return kernel_path("spheres", _SOURCE)


@functools.cache
def _library() -> ctypes.CDLL | None:
    """The compiled search (compiled on first use), or None without a C compiler, on a
    platform whose C ``long`` is not 64 bits, or when the build fails."""
    if ctypes.sizeof(_LONG) != 8 or os.environ.get("POSTUREGEN_NO_NATIVE_SCAN"):
        return None
    lib = kernel_library("spheres", _SOURCE)
    if lib is None:
        return None
    lib.close_pairs.restype = _LONG
    return lib


def available() -> bool:
    """Whether the compiled search is at hand (else the numpy search runs)."""
    return _library() is not None


def _ptr(a: np.ndarray, kind: type) -> ctypes._Pointer:  # type: ignore[name-defined]
    return a.ctypes.data_as(kind)


class SphereSearch:
    """A proxy model's broad-phase tables as C arrays, searched by :meth:`close`."""

    def __init__(
        self,
        radii: np.ndarray,  # (S,) [m]
        joint_pairs: np.ndarray,  # (P, 2)
        group_pair_start: np.ndarray,  # (P + 1,)
        ga: np.ndarray,  # (GP,)
        gb: np.ndarray,  # (GP,)
        group_start: np.ndarray,  # (G + 1,)
    ) -> None:
        def longs(a: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(a, dtype=np.int64)

        self._r = np.ascontiguousarray(radii, dtype=float)
        self._tables = [longs(joint_pairs), longs(group_pair_start), longs(ga), longs(gb)]
        self._tables.append(longs(group_start))
        self._cap = 4096  # the output's first size (grown to what a search found)

    def close(
        self,
        centers: np.ndarray,  # (S, 3) [m] world
        group_bounds: tuple[np.ndarray, np.ndarray],  # centres (G, 3), radii (G,)
        joint_bounds: tuple[np.ndarray, np.ndarray],  # centres (J, 3), radii (J,) by joint id
        slack: np.ndarray,  # (P,) [m]
        links: np.ndarray,  # (k,) joint pair indices
        per_link: int = 0,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, link) of the sphere pairs of ``links`` closer than their slack; with
        ``per_link`` the closest of each joint pair, sorted by distance (the caller measures
        them: the C distances may differ from numpy's in the last bit). Callers check
        :func:`available` first; every array is this call's own (threads may search at once)."""
        lib = _library()
        if lib is None:
            raise PosturegenError("the compiled sphere search is not available")
        best = np.zeros(max(per_link, 1) * _HIT_BYTES // 8)  # the closest of a joint pair
        cap = self._cap
        doubles = [
            np.ascontiguousarray(a, dtype=float)
            for a in (centers, group_bounds[0], group_bounds[1], joint_bounds[0], joint_bounds[1])
        ]
        links = np.ascontiguousarray(links, dtype=np.int64)
        slack = np.ascontiguousarray(slack, dtype=float)
        while True:
            out = [np.empty(cap, dtype=np.int64) for _ in range(3)]
            d = np.empty(cap)
            n = lib.close_pairs(
                _ptr(doubles[0], _DOUBLE_P),
                _ptr(self._r, _DOUBLE_P),
                *(_ptr(a, _DOUBLE_P) for a in doubles[1:]),
                *(_ptr(a, _LONG_P) for a in self._tables[:4]),
                _ptr(self._tables[4], _LONG_P),
                _ptr(links, _LONG_P),
                _LONG(len(links)),
                _ptr(slack, _DOUBLE_P),
                _LONG(per_link),
                best.ctypes.data_as(ctypes.c_void_p),
                *(_ptr(a, _LONG_P) for a in out),
                _ptr(d, _DOUBLE_P),
                _LONG(cap),
            )
            if n <= cap:
                return out[0][:n], out[1][:n], out[2][:n]
            cap = self._cap = int(2 ** np.ceil(np.log2(n)))
