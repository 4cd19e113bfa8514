"""What the value of each contact key is, as JSON Schema: a contact type's ``keys`` map each
key it reads to one of these (or to its own), so that the problem file's schema
(posturegen.io.schema) describes every registered type, a user's own included."""

from __future__ import annotations

from typing import Any

Schema = dict[str, Any]

NUMBER: Schema = {"type": "number"}


def pair(description: str) -> Schema:
    """Two numbers."""
    return {
        "type": "array",
        "items": NUMBER,
        "minItems": 2,
        "maxItems": 2,
        "description": description,
    }


POSITION = pair("the patch's origin in the surface frame (x, y) [m]")
YAW: Schema = {"type": "number", "description": "the patch's yaw about the surface normal [rad]"}
MU: Schema = {"type": "number", "minimum": 0, "description": "friction coefficient"}
FRICTION: Schema = {
    "oneOf": [
        {"const": "cone"},
        {
            "type": "object",
            "properties": {"model": {"enum": ["pyramid", "cone"]}, "faces": {"type": "integer"}},
            "required": ["model"],
            "additionalProperties": False,
        },
    ],
    "description": "the friction model: cone, or a pyramid of `faces` faces",
}
COP_MARGIN: Schema = {
    "type": "number",
    "minimum": 0,
    "description": "the centre of pressure this far inside the loaded region [m]",
}
GRIP: Schema = {
    "type": "number",
    "minimum": 0,
    "description": "the force a hand closed around the surface adds to its friction and lets it "
    "pull with, shared by its force points [N]",
}
UNLOADED: Schema = {"type": "boolean", "description": "the patch held in place, bearing nothing"}
YAW_RANGE = pair("the patch's yaw bounds about the surface normal (min, max) [rad]")
POINT = pair("the point of the patch that touches (x, y), patch frame [m]")
POINTS: Schema = {
    "type": "integer",
    "minimum": 3,
    "description": "force points on the ellipse's boundary",
}
# the ellipse's keys (posturegen.terms.contacts.ellipse)
ELLIPSE: dict[str, Schema] = {
    "formulation": {"enum": ["paper", "support"], "description": "the ellipse-inside rows"},
    "min_radii": pair("the ellipse's smallest radii (rx, ry) [m]"),
    "min_area": {"type": "number", "minimum": 0, "description": "the ellipse's least area [m²]"},
    "maximize_area": {
        "type": "number",
        "minimum": 0,
        "description": "the weight of the ellipse area in the cost (paper eq. 8)",
    },
    "scaling": {
        "oneOf": [{"enum": ["auto", "none"]}, {"type": "number", "exclusiveMinimum": 0}],
        "description": "the thin patch's geometric scaling (paper sec. IV-F)",
    },
}
