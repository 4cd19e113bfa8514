"""A plan's rules: which robot patches may touch which surfaces, how far a new contact may be
from the stance, the contact options of each patch, and the number of contacts.

Format (YAML or a dict; every key optional, defaults per robot from :func:`default_rules`)::

    hands: false               # may the patches named *hand* be used
    release: unload            # unload (the union checked) or lift (the new stance only)
    min_contacts: 1            # a stance holds at least this many contacts
    max_contacts: 4
    patches:
      left_sole:
        surfaces: [ground, "step*"]      # fnmatch patterns of surface names
        reach: 0.6                       # [m] new contact to the nearest sole in contact
        contact: {min_radii: [0.02, 0.02], maximize_area: 10.0, yaw_range: [-0.6, 0.6]}
        mu: 0.7                          # friction once the contact is fixed
        grip: 0.0                        # [N] a hand closed around the surface, once fixed
"""

from __future__ import annotations

import copy
import fnmatch
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _fields as F
from ..errors import InputError
from ..hints import with_hint
from ..model.robot import Robot

SOLE_REACH = 0.75  # × the base's height above the soles at the default posture
HAND_REACH = 2.2  # idem, for a hand (measured from the nearest sole in contact)
SOLE_CONTACT: dict[str, Any] = {
    "min_radii": [0.02, 0.02],
    "maximize_area": 10.0,
    "yaw_range": [-0.6, 0.6],
}
HAND_CONTACT: dict[str, Any] = {"min_radii": [0.015, 0.015]}
RELEASES = ("unload", "lift")
# the keys of a geometric contact that a rule may set (posturegen.spec)
CONTACT_KEYS = ("min_radii", "min_area", "maximize_area", "yaw_range", "formulation", "scaling")


@dataclass(frozen=True)
class PatchRule:
    """Where one robot patch may go: surface name patterns, the reach [m] from the nearest
    sole in contact, the options of its geometric (touch) contact, its μ and grip [N] once
    fixed (posturegen.terms.forces)."""

    surfaces: tuple[str, ...]
    reach: float
    contact: Mapping[str, Any] = field(default_factory=dict)
    mu: float | None = None
    grip: float = 0.0  # [N]

    def allows(self, surface: str) -> bool:
        """The surface matches one of the patterns."""
        return any(fnmatch.fnmatchcase(surface, p) for p in self.surfaces)


@dataclass(frozen=True)
class Rules:
    """Every patch's rule, the use of hands, and the contact count bounds."""

    patches: Mapping[str, PatchRule]
    hands: bool = False
    min_contacts: int = 1
    max_contacts: int = 4
    # "unload": a removal's posture holds the union, the contact resting unloaded where it
    # was; "lift": only the new stance, the patch free (what the scripted climbs check)
    release: str = "unload"

    def movable(self) -> list[str]:
        """The patches the planner may place (hands only when allowed)."""
        return [p for p in self.patches if self.hands or not is_hand(p)]

    def to_dict(self) -> dict[str, Any]:
        """The rules in their input format."""
        return {
            "hands": self.hands,
            "release": self.release,
            "min_contacts": self.min_contacts,
            "max_contacts": self.max_contacts,
            "patches": {
                p: {
                    "surfaces": list(r.surfaces),
                    "reach": r.reach,
                    "contact": copy.deepcopy(dict(r.contact)),
                    **({"mu": r.mu} if r.mu is not None else {}),
                    **({"grip": r.grip} if r.grip > 0 else {}),
                }
                for p, r in self.patches.items()
            },
        }


def is_hand(patch: str) -> bool:
    """A hand patch (by name): the rule ``hands`` gates it."""
    return "hand" in patch


def _base_height(robot: Robot) -> float:
    """Height [m] of the base above the lowest sole patch at the default posture."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.q_init)
    soles = [p for p in robot.patches.values() if "sole" in p.name or "foot" in p.name]
    z = min(
        (float((data.oMf[p.frame_id] * p.T_frame_patch).translation[2]) for p in soles), default=0.0
    )
    return float(robot.q_init[2]) - z


def default_rules(robot: Robot, surfaces: Iterable[str], hands: bool = False) -> Rules:
    """Every patch of the robot on every surface (a hand not on ``ground``); reaches scaled
    by the base's height; soles maximize their ellipse, within ±0.6 rad of the surface's x."""
    names = list(surfaces)
    h = _base_height(robot)
    rules: dict[str, PatchRule] = {}
    for p in robot.patches:
        if is_hand(p):
            allowed = tuple(s for s in names if s != "ground")
            rules[p] = PatchRule(allowed, round(HAND_REACH * h, 3), copy.deepcopy(HAND_CONTACT))
        else:
            rules[p] = PatchRule(("*",), round(SOLE_REACH * h, 3), copy.deepcopy(SOLE_CONTACT))
    return Rules(rules, hands=hands)


def _patch_rule(value: Any, fld: str, base: PatchRule | None) -> PatchRule:
    v = F.require_mapping(value, fld)
    F.check_keys(v, fld, [], ["surfaces", "reach", "contact", "mu", "grip"])
    if base is None:
        base = PatchRule(("*",), 1.0, {})
    surfaces = base.surfaces
    if "surfaces" in v:
        s = v["surfaces"]
        if not isinstance(s, list) or not s:
            raise InputError(
                f"{fld}.surfaces", "expected a non-empty list", "write [ground, 'step*']"
            )
        surfaces = tuple(F.string(x, f"{fld}.surfaces[{i}]") for i, x in enumerate(s))
    reach = F.number(v.get("reach", base.reach), f"{fld}.reach", positive=True)
    contact = dict(base.contact)
    if "contact" in v:
        c = F.require_mapping(v["contact"], f"{fld}.contact")
        F.check_keys(c, f"{fld}.contact", [], CONTACT_KEYS)
        contact = {**contact, **copy.deepcopy(dict(c))}
    mu = base.mu
    if v.get("mu") is not None:
        mu = F.number(v["mu"], f"{fld}.mu", positive=True)
    grip = F.number(v.get("grip", base.grip), f"{fld}.grip", minimum=0.0)
    return PatchRule(surfaces, reach, contact, mu, grip)


def _count(v: Mapping[str, Any], key: str, default: int) -> int:
    return F.integer(v.get(key, default), f"rules.{key}", 1, "write e.g. 2")


def parse_rules(value: Any, defaults: Rules) -> Rules:
    """The rules of a plan: ``value`` (None: the defaults) over ``defaults``, each patch name
    checked against the robot's."""
    if value is None:
        return defaults
    v = F.require_mapping(value, "rules")
    F.check_keys(v, "rules", [], ["hands", "release", "min_contacts", "max_contacts", "patches"])
    release = v.get("release", defaults.release)
    if release not in RELEASES:
        raise InputError("rules.release", f"unknown release {release!r}", "use unload or lift")
    hands = v.get("hands", defaults.hands)
    if not isinstance(hands, bool):
        raise InputError(
            "rules.hands", f"expected true or false, got {hands!r}", "write true or false"
        )
    lo = _count(v, "min_contacts", defaults.min_contacts)
    hi = _count(v, "max_contacts", defaults.max_contacts)
    if hi < lo:
        raise InputError("rules.max_contacts", f"{hi} < min_contacts {lo}", "raise max_contacts")
    patches = dict(defaults.patches)
    given = F.require_mapping(v.get("patches", {}), "rules.patches")
    for name, rule in given.items():
        if name not in defaults.patches:
            known = list(defaults.patches)
            raise InputError(
                f"rules.patches.{name}",
                "unknown robot patch",
                with_hint(str(name), known, f"use one of: {', '.join(known)}"),
            )
        patches[name] = _patch_rule(rule, f"rules.patches.{name}", defaults.patches[name])
    return replace(
        defaults, patches=patches, hands=hands, min_contacts=lo, max_contacts=hi, release=release
    )


def patch_positions(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    """World position (3,) [m] of every patch's origin at posture ``q``."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, q)
    return {
        n: np.array((data.oMf[p.frame_id] * p.T_frame_patch).translation)
        for n, p in robot.patches.items()
    }
