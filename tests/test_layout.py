"""The names user code imported before the sub-packages still give the same objects."""

from __future__ import annotations

import importlib

import pytest

RE_EXPORTS = {
    "posturegen.geometry": [
        "posturegen.model.geometry",
        "posturegen.model.ellipse_fit",
        "posturegen.model.ellipse_rows",
    ],
    "posturegen.stance": ["posturegen.climb.stance"],
    "posturegen.scenes": ["posturegen.climb.scenes"],
    "posturegen.sequence": ["posturegen.climb.sequence"],
    "posturegen.spec": ["posturegen.io.problem_file"],
    "posturegen.inspection": ["posturegen.solver.inspection"],
}


@pytest.mark.parametrize("old", sorted(RE_EXPORTS))
def test_old_module_names_re_export_the_same_objects(old):
    module = importlib.import_module(old)
    homes = [importlib.import_module(m) for m in RE_EXPORTS[old]]
    assert module.__all__
    for name in module.__all__:
        owners = [h for h in homes if getattr(h, name, None) is getattr(module, name)]
        assert owners, f"{old}.{name} is not the object of {RE_EXPORTS[old]}"
