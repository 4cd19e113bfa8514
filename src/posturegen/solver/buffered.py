"""A CasADi function evaluated into preallocated numpy arrays (CasADi's FunctionBuffer): the
caller writes its inputs in place, the call writes its outputs' nonzeros in place. A call
through ``Function.__call__`` converts each argument to a DM and each result back: Talos'
18,093 collision parameters cost 0.6 ms a call that way, more than a reach's Jacobian.

A Buffered holds its function's memory: one call at a time (its owner's lock)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np


class Buffered:
    """``fn`` evaluated into arrays: ``inputs`` (given, or zeros of each input's nonzeros) and
    ``outputs`` (each output's nonzeros, in CasADi's column-major order)."""

    def __init__(self, fn: ca.Function, inputs: list[np.ndarray] | None = None) -> None:
        if inputs is None:
            inputs = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self.fn = fn
        self.inputs = inputs
        self.outputs = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        buffer, self._trigger = fn.buffer()
        for i, a in enumerate(inputs):
            buffer.set_arg(i, memoryview(a))
        for i, r in enumerate(self.outputs):
            buffer.set_res(i, memoryview(r))
        self._buffer = buffer  # kept alive with the arrays it points to
        self.sparsity = [fn.sparsity_out(i) for i in range(fn.n_out())]

    def __call__(self) -> list[np.ndarray]:
        """Evaluate at the inputs' current values; the outputs' nonzeros (the buffer's own
        arrays, overwritten at the next call)."""
        self._trigger()
        return self.outputs

    def arg(self, name: str) -> np.ndarray:
        """The input array named ``name`` (write it in place)."""
        return self.inputs[self.fn.index_in(name)]

    def res(self, name: str) -> np.ndarray:
        """The output array named ``name`` (its nonzeros; read it after a call)."""
        return self.outputs[self.fn.index_out(name)]

    def stats(self) -> dict[str, Any]:
        """The statistics of the last call (an nlpsol's return status, iterations, times)."""
        return dict(self._buffer.stats())

    def column(self, i: int) -> np.ndarray:
        """Output ``i`` dense, flattened column-major (rows × cols,), zeros where it has no
        nonzero: a copy."""
        sp = self.sparsity[i]
        if sp.is_dense():
            return self.outputs[i].copy()
        rows, cols = sp.get_triplet()
        dense = np.zeros(sp.numel())
        dense[np.asarray(cols, dtype=np.intp) * sp.size1() + np.asarray(rows, dtype=np.intp)] = (
            self.outputs[i]
        )
        return dense

    def scatter(self, i: int) -> Callable[[np.ndarray, np.ndarray], None]:
        """A function writing output ``i``'s nonzeros into a dense (rows, cols) array (zeros
        elsewhere)."""
        sp = self.sparsity[i]
        rows, cols = sp.get_triplet()
        flat = np.asarray(rows, dtype=np.intp) * sp.size2() + np.asarray(cols, dtype=np.intp)

        def write(nonzeros: np.ndarray, dense: np.ndarray) -> None:
            dense.ravel()[flat] = nonzeros

        return write
