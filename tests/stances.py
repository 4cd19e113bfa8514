"""Problem dicts the tests share: Talos standing on a 2 m × 2 m ground."""

from __future__ import annotations

from typing import Any


def talos_on_ground(**options: Any) -> dict[str, Any]:
    """Talos' soles fixed on the ground 0.1 m either side of the origin, yaw 0, μ 0.7, from
    half-sitting; ``options`` added to the problem's options. A new dict each call."""
    return {
        "robot": "talos",
        "mu": 0.7,
        "surfaces": [
            {
                "name": "ground",
                "position": [0, 0, 0],
                "rpy": [0, 0, 0],
                "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]],
            }
        ],
        "contacts": [
            {
                "robot_patch": side + "_sole",
                "surface": "ground",
                "type": "fixed",
                "position": [0.0, y],
                "yaw": 0.0,
            }
            for side, y in (("left", 0.1), ("right", -0.1))
        ],
        "options": {"initial": "half_sitting", **options},
    }
