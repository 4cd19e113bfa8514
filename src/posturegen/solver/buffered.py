"""A CasADi function evaluated into preallocated numpy arrays (CasADi's FunctionBuffer): the
caller writes its inputs in place, the call writes its outputs' nonzeros in place. A call
through ``Function.__call__`` converts each argument to a DM and each result back: Talos'
18,093 collision parameters cost 0.6 ms a call that way, more than a reach's Jacobian.

A Buffered holds its function's memory: one call at a time (its owner's lock)."""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from .._compiler import capsule_pointer

# CasADi's evaluation of a FunctionBuffer, ``void casadi::_function_buffer_eval(void*)``: what
# a Buffered's call runs, callable from C with :meth:`Buffered.address`
_EVAL_SYMBOL = "_ZN6casadi21_function_buffer_evalEPv"


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

    def positions(self, i: int) -> np.ndarray:
        """(nnz,) where output ``i``'s nonzeros go in its dense form flattened row-major."""
        sp = self.sparsity[i]
        rows, cols = sp.get_triplet()
        return np.asarray(rows, dtype=np.intp) * sp.size2() + np.asarray(cols, dtype=np.intp)

    def scatter(self, i: int) -> Callable[[np.ndarray, np.ndarray], None]:
        """A function writing output ``i``'s nonzeros into a dense (rows, cols) array (zeros
        elsewhere)."""
        flat = self.positions(i)

        def write(nonzeros: np.ndarray, dense: np.ndarray) -> None:
            dense.ravel()[flat] = nonzeros

        return write

    def address(self) -> int:
        """The C address of this call's FunctionBuffer: ``eval_address()`` called on it
        evaluates the function into the arrays, as a call does (the Buffered must live)."""
        return capsule_pointer(self._buffer._self())


@functools.cache
def eval_address() -> int | None:
    """The C address of CasADi's FunctionBuffer evaluation (None when its library does not
    export it under the name this CasADi version gives it)."""
    folder = Path(ca.__file__).parent
    for path in sorted(folder.glob("libcasadi.so*")) + sorted(folder.glob("libcasadi*.dylib")):
        try:
            return int(ctypes.cast(ctypes.CDLL(str(path))[_EVAL_SYMBOL], ctypes.c_void_p).value)
        except (OSError, AttributeError):
            continue
    return None
