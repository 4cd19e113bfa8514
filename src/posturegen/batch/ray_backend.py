"""The Ray backend: the same chunks on the actors of a Ray cluster (``pip install
'posturegen[ray]'``).

One actor per worker, one CPU each, lives for the whole batch and keeps its solver structures
(the same worker code as the local pool: posturegen.batch.worker). ``address`` None starts a
local Ray instance with ``workers`` CPUs (or joins the one this process already started);
``auto`` joins the cluster this machine belongs to (``ray start``), ``ray://HOST:10001`` a
remote one through Ray Client. Every node needs posturegen installed, the same version, and
the robots' files at the same paths (bundled robots: nothing more). An actor that dies is
restarted by Ray; the lost chunk's jobs are run again alone (posturegen.batch.schedule).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from typing import Any

from ..errors import InputError
from .jobs import BatchItem, Job, read_file
from .worker import WorkerInfo, run_chunk, warm, worker_info


def _ray() -> Any:
    """The ray module, or the one-line error that says how to install it."""
    try:
        import ray  # optional dependency: only this backend needs it
    except ImportError as exc:
        raise InputError(
            "backend", "ray is not installed", "pip install 'posturegen[ray]', or use local"
        ) from exc
    return ray


def _connect(ray: Any, address: str | None, workers: int | None) -> None:
    """Join the cluster at ``address``, or start a local instance of ``workers`` CPUs."""
    try:
        ray.init(
            address=address,
            num_cpus=None if address else (workers or os.cpu_count() or 1),
            include_dashboard=False,
            log_to_driver=False,
            logging_level=logging.ERROR,
        )
    except (ConnectionError, RuntimeError, ValueError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputError(
            "address",
            f"cannot join the Ray cluster at {address} ({first})",
            "start one with 'ray start --head', or give its address (auto, ray://HOST:10001)",
        ) from exc


RESTART_WAIT_S = 300.0  # [s] how long recover() waits for Ray to restart the dead actors
RESTART_POLL_S = 0.2  # [s] between two questions to a restarting actor


class _Worker:
    """A Ray actor: solves chunks with this process's cached structures."""

    def __init__(self, warm_jobs: Sequence[Job], diagnose: bool) -> None:
        self.diagnose = diagnose
        warm(warm_jobs)

    def run(self, jobs: list[Job]) -> list[BatchItem]:
        return run_chunk(jobs, self.diagnose)

    def info(self) -> WorkerInfo:
        return worker_info()


class RayBackend:
    """``workers`` actors (default: the cluster's CPUs), two chunks in flight each."""

    def __init__(
        self,
        workers: int | None = None,
        diagnose: bool = False,
        warm: Sequence[Job] = (),
        address: str | None = None,
    ) -> None:
        self._ray = ray = _ray()
        self._owns = not ray.is_initialized()
        if self._owns:
            _connect(ray, address, workers)
        available = int(ray.cluster_resources().get("CPU", 0))
        self.workers = workers or available
        if not 1 <= self.workers <= available:
            self.close()
            raise InputError(
                "workers",
                f"{self.workers} workers on a Ray cluster of {available} CPUs",
                f"give at most {available} (one CPU a worker)",
            )
        self.slots = 2 * self.workers
        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=0)(_Worker)
        self._actors = [actor.remote(list(warm), diagnose) for _ in range(self.workers)]
        self._load = [0] * self.workers  # chunks in flight per actor
        self._owner: dict[Any, int] = {}

    def submit(self, jobs: list[Job]) -> Any:
        """Run a chunk on the actor with the fewest chunks in flight (its files read here:
        the actor may be on another machine)."""
        k = min(range(self.workers), key=self._load.__getitem__)
        ref = self._actors[k].run.remote([read_file(job) for job in jobs])
        self._load[k] += 1
        self._owner[ref] = k
        return ref

    def wait(self, handles: list[Any]) -> list[tuple[Any, list[BatchItem] | BaseException]]:
        """The chunks done (at least one): their items, or what lost them."""
        ready, _ = self._ray.wait(handles, num_returns=1)
        out: list[tuple[Any, list[BatchItem] | BaseException]] = []
        for ref in ready:
            self._load[self._owner.pop(ref)] -= 1
            try:
                out.append((ref, self._ray.get(ref)))
            except self._ray.exceptions.RayError as exc:
                out.append((ref, exc))
        return out

    def crashed(self, exc: BaseException) -> bool:
        """The actor died (Ray restarts it)."""
        errors = self._ray.exceptions
        return isinstance(exc, errors.RayActorError | errors.WorkerCrashedError)

    def recover(self) -> None:
        """Wait until every actor answers again (Ray restarts a dead one, whose constructor
        warms it up): a suspect sent to an actor still restarting was lost to Ray's
        ActorUnavailableError and called a crash (11 problems, one killer: three innocent
        ones lost so on the loaded 2-core machine)."""
        actor_error = self._ray.exceptions.RayActorError
        deadline = time.monotonic() + RESTART_WAIT_S
        for actor in self._actors:
            while time.monotonic() < deadline:
                try:
                    self._ray.get(actor.info.remote(), timeout=deadline - time.monotonic())
                    break
                except actor_error:  # dying, or restarting: ask again
                    time.sleep(RESTART_POLL_S)
                except self._ray.exceptions.GetTimeoutError:
                    break

    def ready(self) -> list[WorkerInfo]:
        """Block until every actor is up and warm; their WorkerInfo, one each."""
        return list(self._ray.get([a.info.remote() for a in self._actors]))

    def close(self) -> None:
        """Stop the actors, and the Ray instance when this backend started it."""
        for actor in getattr(self, "_actors", []):
            self._ray.kill(actor)
        if self._owns:
            self._ray.shutdown()
