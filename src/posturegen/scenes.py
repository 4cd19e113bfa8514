"""The shipped scenes, by their name before the sub-packages (kept for user code; the module is
:mod:`posturegen.climb.scenes`). A re-export only: nothing in the package imports it."""

from .climb.scenes import SCENES, SceneInfo, scene

__all__ = ["SCENES", "SceneInfo", "scene"]
