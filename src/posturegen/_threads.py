"""Single-threaded BLAS unless the user chose otherwise (imported first by the package).

A posture solve runs on one core; the BLAS under numpy and under IPOPT's MUMPS otherwise start
worker threads that spin beside IPOPT. On the 2-core machine this made Talos' solves 10-40 %
slower and their times erratic (talos-near-body-free: 5.1-7.5 ms median from one run to the
next, 5.2-5.7 ms single-threaded). OpenBLAS reads the variable when it loads, so it has no
effect when numpy was imported before posturegen; set ``OPENBLAS_NUM_THREADS`` to override."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
