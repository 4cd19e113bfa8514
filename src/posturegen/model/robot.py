"""Robots: a Pinocchio model with a free-flyer root, torque limits and named contact patches.

A *patch* is a convex polygon in its own frame, whose z axis is the patch's outward normal,
rigidly attached to a Pinocchio frame: ``T_frame_patch``. Bundled robots come from the
``example-robot-data`` package with patch files shipped in ``posturegen/data/robots``.
"""

from __future__ import annotations

import importlib.metadata
import importlib.resources
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _fields as F
from .._cache import memoize
from ..errors import InputError, ModelError
from ..hints import with_hint
from .geometry import ConvexPolygon
from .kinematics import CasadiKinematics

# robots shipped by name: the first three from example-robot-data, the paper's two in
# posturegen/data/models (public data that is not on PyPI; see its PROVENANCE.md)
BUNDLED = ("talos", "g1", "romeo", "hrp2", "atlas")


def shipped_models_dir() -> Path:
    """Folder ``data/models`` of posturegen: the HRP-2 and ATLAS models it ships."""
    return Path(str(importlib.resources.files("posturegen") / "data" / "models"))


def example_robot_data_dir() -> Path:
    """Folder ``robots/`` of the installed example-robot-data package."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:  # pragma: no cover - install issue
        raise ModelError(
            "example-robot-data is not installed (pip install example-robot-data)"
        ) from exc
    root = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    if not root.is_dir():  # pragma: no cover - install issue
        raise ModelError(f"example-robot-data has no robots folder at {root}")
    return root


@dataclass(frozen=True)
class Patch:
    """A convex contact polygon on the robot: vertices in the patch frame, z = outward normal."""

    name: str
    frame: str  # Pinocchio frame the patch is attached to
    frame_id: int
    joint_id: int  # parent joint of that frame
    T_frame_patch: pin.SE3  # patch in its frame
    T_joint_patch: pin.SE3  # patch in the frame's parent joint
    polygon: ConvexPolygon


@dataclass
class Robot:
    """A humanoid model ready for posture generation."""

    name: str
    model: pin.Model
    urdf: Path
    srdf: Path | None
    package_dirs: tuple[Path, ...]
    patches: dict[str, Patch]
    q_init: np.ndarray  # (nq,) default initial posture
    reference_configurations: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.kinematics = CasadiKinematics(self.model)
        self.nj = self.model.nv - 6
        # Torque limits of the actuated joints [N·m or N]; inf where the URDF gives none.
        effort = np.array(self.model.effortLimit[6:], dtype=float)
        effort[~np.isfinite(effort) | (effort <= 0) | (effort > 1e10)] = np.inf
        self.effort_limit = effort  # (nj,)
        self.q_lower = np.array(self.model.lowerPositionLimit[7:], dtype=float)  # (nj,)
        self.q_upper = np.array(self.model.upperPositionLimit[7:], dtype=float)  # (nj,)
        self.q_lower[self.q_lower < -1e10] = -np.inf
        self.q_upper[self.q_upper > 1e10] = np.inf
        self.joint_names = [self.model.names[i] for i in self.kinematics.actuated_joint_ids()]
        self._collision_model: pin.GeometryModel | None = None
        # posturegen.collision.proxies.ProxyModel, fitted on first use
        self._proxy_model: Any = None
        # the resolved paths of the posture files' robot entry (resolved once: each solve
        # writes one)
        self._entry: dict[str, Any] | None = None

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return self.kinematics.total_mass

    @property
    def weight(self) -> float:
        """Total weight m·|g| [N]."""
        return self.mass * float(np.linalg.norm(self.model.gravity.linear))

    def frame_id(self, name: str, field_name: str = "frame") -> int:
        """Pinocchio frame id, or an InputError naming the field."""
        if not self.model.existFrame(name):
            raise InputError(
                field_name,
                f"robot '{self.name}' has no frame '{name}'",
                with_hint(name, _frame_names(self.model), "use a link or frame name of the URDF"),
            )
        return int(self.model.getFrameId(name))

    def patch(self, name: str, field_name: str = "robot_patch") -> Patch:
        """A named patch, or an InputError listing the known ones."""
        if name not in self.patches:
            raise InputError(
                field_name,
                f"robot '{self.name}' has no patch '{name}'",
                with_hint(
                    name,
                    self.patches,
                    f"known patches: {', '.join(sorted(self.patches)) or 'none'}",
                ),
            )
        return self.patches[name]

    def on_ground(self, q: np.ndarray) -> np.ndarray:
        """q (nq,) with its base raised so that the lowest sole-patch vertex is at z = 0, when
        the base translation q[0:3] is zero (a URDF's root at the origin puts the feet under
        the ground; a solver started there can settle in a crouch) and the robot has patches
        named ``*sole``. Any other q is returned unchanged (a copy)."""
        q = np.array(q, dtype=float)
        soles = [p for n, p in self.patches.items() if n.endswith("sole")]
        if not soles or np.any(q[0:3] != 0.0):
            return q
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, q)
        lowest = np.inf
        for p in soles:
            T_world_patch = data.oMf[p.frame_id] * p.T_frame_patch
            v = p.polygon.vertices  # (k, 2) in the patch plane
            z_world = v @ T_world_patch.rotation[2, :2] + T_world_patch.translation[2]  # (k,)
            lowest = min(lowest, float(z_world.min()))
        q[2] = -lowest
        return q

    def initial_configuration(
        self, initial: Any = None, field_name: str = "options.initial"
    ) -> np.ndarray:
        """q (nq,) from a reference-configuration name, a ``{joint: value}`` mapping over the
        neutral posture, an explicit list of the nq numbers, or the default. Named and mapped
        postures whose base is at the origin stand on z = 0 (:meth:`on_ground`)."""
        if initial is None:
            return self.q_init.copy()
        if isinstance(initial, Mapping):
            return self.on_ground(self.configuration_from_joints(initial, field_name))
        if isinstance(initial, str):
            if initial not in self.reference_configurations:
                known = ", ".join(sorted(self.reference_configurations)) or "none"
                raise InputError(
                    field_name,
                    f"unknown reference posture '{initial}'",
                    with_hint(
                        initial,
                        self.reference_configurations,
                        f"known: {known}, or give the {self.model.nq} numbers of q",
                    ),
                )
            return self.on_ground(self.reference_configurations[initial])
        q = F.vector(initial, self.model.nq, field_name)
        if abs(np.linalg.norm(q[3:7]) - 1.0) > 1e-6:
            raise InputError(
                field_name,
                "the base quaternion q[3:7] is not unit",
                "give a unit quaternion (x, y, z, w)",
            )
        return q

    def configuration_from_joints(
        self, values: Mapping[str, Any], field_name: str = "initial"
    ) -> np.ndarray:
        """q (nq,): the neutral posture (base at the origin, identity orientation) with the
        named actuated joints set to the given values [rad or m], each inside its limits."""
        model = self.model
        q = pin.neutral(model)
        q[2] = 0.0
        for name, value in values.items():
            fld = f"{field_name}.{name}"
            jid = int(model.getJointId(name)) if isinstance(name, str) else model.njoints
            if jid <= 1 or jid >= model.njoints:  # 0: universe, 1: the free-flyer root
                known = ", ".join(self.joint_names[:4])
                raise InputError(
                    fld,
                    f"robot '{self.name}' has no actuated joint '{name}'",
                    with_hint(
                        str(name), self.joint_names, f"use joint names of the URDF ({known}, ...)"
                    ),
                )
            joint = model.joints[jid]
            x = F.number(value, fld)
            i = joint.idx_q
            if joint.nq == 1:
                lo = float(model.lowerPositionLimit[i])
                hi = float(model.upperPositionLimit[i])
                if not lo - 1e-9 <= x <= hi + 1e-9:
                    raise InputError(
                        fld,
                        f"{x} is outside the joint limits [{lo:.6g}, {hi:.6g}]",
                        "give a value inside the limits",
                    )
                q[i] = x
            elif joint.nq == 2 and joint.nv == 1:  # unbounded revolute joint: (cos, sin)
                q[i : i + 2] = np.cos(x), np.sin(x)
            else:
                raise InputError(
                    fld,
                    f"joint '{name}' has {joint.nq} configuration numbers",
                    "set only one-degree-of-freedom joints by name",
                )
        return q

    def collision_model(self) -> pin.GeometryModel:
        """The URDF's collision geometry (meshes), loaded on first use."""
        if self._collision_model is None:
            try:
                self._collision_model = pin.buildGeomFromUrdf(
                    self.model,
                    str(self.urdf),
                    pin.GeometryType.COLLISION,
                    package_dirs=[str(p) for p in self.package_dirs],
                )
            except ValueError as exc:
                raise ModelError(f"cannot load collision meshes of {self.urdf}: {exc}") from exc
        return self._collision_model

    def to_dict(self) -> dict[str, Any]:
        """The ``robot`` entry of a posture file (a new dict each call)."""
        if self._entry is None:
            self._entry = {
                "name": self.name,
                "urdf": str(self.urdf.resolve()),
                "srdf": str(self.srdf.resolve()) if self.srdf else None,
                "package_dirs": [str(p.resolve()) for p in self.package_dirs],
            }
        return {**self._entry, "package_dirs": list(self._entry["package_dirs"])}


def _frame_names(model: pin.Model) -> list[str]:
    """The names of a model's frames (links, joints and others)."""
    return [str(f.name) for f in model.frames]


def _load_patches(model: pin.Model, data: Any, field_name: str) -> dict[str, Patch]:
    patches_raw = F.require_mapping(data, field_name)
    patches: dict[str, Patch] = {}
    for name, spec in patches_raw.items():
        fld = f"{field_name}.{name}"
        spec = F.require_mapping(spec, fld)
        F.check_keys(spec, fld, ["frame", "vertices"], ["position", "rpy"])
        frame = F.string(spec["frame"], f"{fld}.frame")
        if not model.existFrame(frame):
            raise InputError(
                f"{fld}.frame",
                f"the model has no frame '{frame}'",
                with_hint(frame, _frame_names(model), "use a link or frame name of the URDF"),
            )
        fid = int(model.getFrameId(frame))
        T = F.placement(spec.get("position", [0, 0, 0]), spec.get("rpy", [0, 0, 0]), fld)
        poly = ConvexPolygon(
            F.points2d(spec["vertices"], f"{fld}.vertices"), field=f"{fld}.vertices"
        )
        f = model.frames[fid]
        patches[str(name)] = Patch(
            str(name), frame, fid, int(f.parentJoint), T, f.placement * T, poly
        )
    return patches


def read_patch_file(path: Path) -> dict[str, Any]:
    """Parse a patch YAML file (see docs/file-formats.md, "Patch file")."""
    data = F.read_yaml(path, "patch YAML file")
    return dict(F.require_mapping(data, "robot.patches"))


def _bundled_patch_file(name: str) -> Path:
    return Path(str(importlib.resources.files("posturegen") / "data" / "robots" / f"{name}.yaml"))


def build_robot(
    name: str,
    urdf: Path,
    srdf: Path | None,
    package_dirs: tuple[Path, ...],
    patch_data: dict[str, Any],
    initial: Any = None,
) -> Robot:
    """Load a URDF with a free-flyer root, its SRDF reference postures, and patches."""
    if not urdf.is_file():
        raise InputError("robot.urdf", f"no file {urdf}", "give the path of an existing URDF")
    if srdf is not None and not srdf.is_file():
        raise InputError("robot.srdf", f"no file {srdf}", "give the path of an existing SRDF")
    try:
        model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    except (ValueError, RuntimeError) as exc:
        raise InputError(
            "robot.urdf", f"Pinocchio cannot parse {urdf}: {exc}", "fix the URDF"
        ) from exc
    refs: dict[str, np.ndarray] = {}
    if srdf is not None:
        try:
            pin.loadReferenceConfigurations(model, str(srdf), False)
        except (ValueError, RuntimeError) as exc:
            raise InputError("robot.srdf", f"cannot read {srdf}: {exc}", "fix the SRDF") from exc
        for entry in model.referenceConfigurations:
            refs[str(entry.key())] = np.array(entry.data(), dtype=float)
    patches = _load_patches(model, patch_data.get("patches", {}), "patches")
    q_neutral = pin.neutral(model)
    q_neutral[2] = 0.0
    robot = Robot(name, model, urdf, srdf, package_dirs, patches, q_neutral, refs)
    init = initial if initial is not None else patch_data.get("initial")
    robot.q_init = robot.initial_configuration(init, "initial") if init is not None else q_neutral
    robot.q_init = robot.on_ground(robot.q_init)
    return robot


@memoize("bundled robots", 8)
def load_bundled(name: str) -> Robot:
    """A robot shipped with posturegen, by name: its patch file names the URDF (and SRDF)
    relative to example-robot-data's robots folder, or with ``models: posturegen`` relative
    to posturegen's own ``data/models`` (then also a package directory, with the URDF's)."""
    if name not in BUNDLED:
        raise InputError(
            "robot",
            f"unknown robot '{name}'",
            with_hint(
                name, BUNDLED, f"bundled robots: {', '.join(BUNDLED)}, or give {{urdf: PATH, ...}}"
            ),
        )
    data = read_patch_file(_bundled_patch_file(name))
    if data.get("models") == "posturegen":
        root = shipped_models_dir()
        # package:// meshes (ATLAS) from the models folder, relative ones (HRP-2) from the URDF's
        package_dirs: tuple[Path, ...] = (root, (root / data["urdf"]).parent)
    else:
        root = example_robot_data_dir()
        package_dirs = (root.parent.parent,)
    return build_robot(
        name,
        root / data["urdf"],
        root / data["srdf"] if data.get("srdf") else None,
        package_dirs,
        data,
    )


@memoize("custom robots", 8)
def _load_custom(
    urdf: str,
    srdf: str | None,
    patches: str | None,
    package_dirs: tuple[str, ...],
    name: str | None = None,
) -> Robot:
    """A robot from its files, cached per files and name (a Robot is shared by every caller
    that asks for the same one: it is never renamed)."""
    urdf_path = Path(urdf).expanduser().resolve()
    data: dict[str, Any] = {}
    if patches is not None:
        bundled = _bundled_patch_file(patches)
        data = read_patch_file(
            bundled if ("/" not in patches and bundled.is_file()) else Path(patches)
        )
    return build_robot(
        name or urdf_path.stem,
        urdf_path,
        Path(srdf).expanduser().resolve() if srdf else None,
        tuple(Path(p).expanduser().resolve() for p in package_dirs) or (urdf_path.parent,),
        data,
    )


def load_robot(spec: Any, base_dir: Path | None = None) -> Robot:
    """A robot from a bundled name or ``{urdf, srdf, patches, package_dirs}`` (paths relative
    to ``base_dir``, the problem file's folder)."""
    if isinstance(spec, str):
        return load_bundled(spec)
    spec = F.require_mapping(spec, "robot")
    F.check_keys(spec, "robot", ["urdf"], ["srdf", "patches", "package_dirs", "name"])
    base = base_dir or Path.cwd()

    def rel(value: Any, fld: str) -> str:
        return str((base / Path(F.string(value, fld)).expanduser()).resolve())

    patches = spec.get("patches")
    if patches is not None:
        patches = F.string(patches, "robot.patches")
        if "/" in patches or patches.endswith((".yaml", ".yml")):
            patches = rel(patches, "robot.patches")
    dirs = spec.get("package_dirs", [])
    if not isinstance(dirs, list):
        raise InputError("robot.package_dirs", "expected a list of folders", "write [PATH, ...]")
    return _load_custom(
        rel(spec["urdf"], "robot.urdf"),
        rel(spec["srdf"], "robot.srdf") if spec.get("srdf") else None,
        patches,
        tuple(rel(d, f"robot.package_dirs[{i}]") for i, d in enumerate(dirs)),
        F.string(spec["name"], "robot.name") if "name" in spec else None,
    )
