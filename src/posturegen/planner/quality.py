"""Contact quality along a sequence, from its posture files: the size of each loaded
contact's region (inradius of the intersection of the patch and the surface at the realized
pose, or the ellipse's smaller radius when it has one) and how deep its centre of pressure is
inside it (paper sec. IV-D: the larger, the more robust; of the pressures with a hand's grip,
as posturegen.verify checks it)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import shapely

from ..model.robot import Robot, load_robot
from ..verify import grip_per_point

LOADED = 0.05  # a contact bearing at least this share of the total normal force counts


@dataclass(frozen=True)
class Quality:
    """Minimum over every loaded contact of every posture [m]."""

    region: float
    cop_depth: float

    def to_dict(self) -> dict[str, float]:
        return {"min_region_inradius_m": self.region, "min_cop_depth_m": self.cop_depth}


def _in_plane(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """World points (k, 3) in the frame of the homogeneous placement T (4, 4)."""
    return (pts - T[:3, 3]) @ T[:3, :3]


def _region(contact: Mapping[str, Any], T_ws: np.ndarray, T_wc: np.ndarray) -> shapely.Polygon:
    """The contact's region in the surface plane: its ellipse (as a polygon) or the
    intersection of both polygons."""
    ell = contact.get("ellipse")
    if ell is not None:
        c = _in_plane(T_ws, np.array([ell["center"]]))[0, :2]
        a1, a2 = ((T_ws[:3, :3].T @ np.asarray(a, dtype=float))[:2] for a in ell["axes"])
        t = np.linspace(0, 2 * np.pi, 128, endpoint=False)
        return shapely.Polygon(c + np.outer(np.cos(t), a1) + np.outer(np.sin(t), a2))
    v_c = np.array(contact["robot_patch"]["vertices"], dtype=float)
    v_w = np.column_stack([v_c, np.zeros(len(v_c))]) @ T_wc[:3, :3].T + T_wc[:3, 3]
    patch = shapely.Polygon(_in_plane(T_ws, v_w)[:, :2]).convex_hull
    return patch.intersection(shapely.Polygon(contact["surface"]["vertices"]))


def contact_quality(posture: Mapping[str, Any], frames: Mapping[str, np.ndarray]) -> Quality:
    """``frames``: world placement (4, 4) of every patch frame named in the posture."""
    rows = []
    totals = []
    for c in posture.get("contacts", []):
        forces = c.get("forces") or []
        if not forces:
            continue
        T_ws = np.array(c["surface"]["placement"], dtype=float)
        n = T_ws[:3, 2]
        fn = np.array([f["force"] for f in forces], dtype=float) @ n  # (k,) [N] the load
        totals.append(float(fn.sum()))
        pressed = fn + grip_per_point(c)  # (k,) [N] with a hand's grip: its pressure
        T_wc = frames[c["robot_patch"]["frame"]] @ np.array(c["robot_patch"]["placement"])
        region = _region(c, T_ws, T_wc)
        pts = _in_plane(T_ws, np.array([f["point"] for f in forces], dtype=float))[:, :2]
        cop = pressed @ pts / max(float(pressed.sum()), 1e-12)
        depth = region.exterior.distance(shapely.Point(*cop))
        if not region.contains(shapely.Point(*cop)):
            depth = -depth
        radius = (
            float(shapely.maximum_inscribed_circle(region).length) if not region.is_empty else 0.0
        )
        rows.append((float(fn.sum()), radius, float(depth)))
    total = sum(totals) or 1.0
    loaded = [r for r in rows if r[0] >= LOADED * total] or rows
    if not loaded:
        return Quality(float("nan"), float("nan"))
    return Quality(min(r[1] for r in loaded), min(r[2] for r in loaded))


def worst(qualities: Iterable[Quality]) -> Quality:
    """The minimum of each measure over a sequence."""
    qs = list(qualities)
    return Quality(min(q.region for q in qs), min(q.cop_depth for q in qs))


def posture_quality(posture: Mapping[str, Any], robot: Robot) -> Quality:
    """The quality of a posture file's content for its robot."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, np.array(posture["q"], dtype=float))
    names = {c["robot_patch"]["frame"] for c in posture.get("contacts", [])}
    frames = {n: data.oMf[model.getFrameId(n)].homogeneous for n in names}
    return contact_quality(posture, frames)


def sequence_quality(directory: str | Path) -> Quality:
    """The worst quality over the verified postures of a ``sequence.json`` directory (a
    climb's or a plan's)."""
    folder = Path(directory)
    index = json.loads((folder / "sequence.json").read_text())
    robot = load_robot(index["robot"])
    out = []
    for stage in index["stages"]:
        if stage["success"]:
            out.append(posture_quality(json.loads((folder / stage["posture"]).read_text()), robot))
    return worst(out) if out else Quality(float("nan"), float("nan"))
