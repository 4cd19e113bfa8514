"""Problems of the batch tests: Talos standing at the demo's stance and reaching targets."""

from __future__ import annotations

import copy
import os
from typing import Any

import yaml

from posturegen.cli import _demo_dir

STAND: dict[str, Any] = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
FAR = [2.0, -0.3, 0.9]  # 2.2 m from the feet: beyond reach (a failure, diagnosed)


def stand(target: list[float], name: str | None = None) -> dict[str, Any]:
    """The demo problem with another right-gripper target [m]."""
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = list(target)
    if name is not None:
        data["name"] = name
    return data


class Killer:
    """Unpickled in a worker, it ends the worker's process at once (a crash: no exception,
    no cleanup)."""

    def __reduce__(self) -> tuple[Any, tuple[int]]:
        return os._exit, (3,)


def killer(name: str = "killer") -> dict[str, Any]:
    """A problem dict whose travel to a worker kills the worker."""
    data = stand([0.4, -0.3, 0.9], name)
    data["mu"] = Killer()
    return data
