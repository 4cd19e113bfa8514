"""Input hints (posturegen.hints: close names in errors, misspelt keys) and warnings for
implausible values (posturegen.plausible)."""

from __future__ import annotations

import copy
import string

import numpy as np
import pinocchio as pin
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen.cli import _demo_dir, main
from posturegen.errors import ImplausibleValueWarning, InputError
from posturegen.hints import close_names, did_you_mean
from posturegen.io.problem_file import problem_from_dict
from posturegen.model.robot import load_bundled
from posturegen.plausible import chain_length

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


def _edited(**changes: object) -> dict:
    data = copy.deepcopy(STAND)
    for path, value in changes.items():
        node = data
        *keys, last = path.split("__")
        for k in keys:
            node = node[int(k)] if k.isdigit() else node[k]
        node[int(last) if last.isdigit() else last] = value
    return data


def _error(data: dict) -> str:
    with pytest.raises(InputError) as info:
        problem_from_dict(data)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_unknown_frame_on_g1_names_the_close_frames():
    data = _edited(robot="g1", tasks__0__frame="right_hand")
    message = _error(data)
    assert message.startswith("tasks[0].frame: robot 'g1' has no frame 'right_hand' (did you mean ")
    assert "right_hand_palm_link" in message


def test_misspelt_key_is_reported_as_misspelt():
    data = copy.deepcopy(STAND)
    data["contacts"][0]["robot_pach"] = data["contacts"][0].pop("robot_patch")
    message = _error(data)
    assert message.startswith("contacts[0].robot_pach: unknown key, did you mean robot_patch?")
    data = copy.deepcopy(STAND)
    data["optoins"] = data.pop("options")
    assert _error(data).startswith("problem.optoins: unknown key, did you mean options?")


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        ("contacts__0__robot_patch", "left_paw", "did you mean left_hand?"),
        ("contacts__0__surface", "grund", "did you mean ground?"),
        ("robot", "talso", "did you mean talos"),
        ("contacts__0__type", "fixd", "did you mean fixed?"),
        ("options__initial", "half_siting", "did you mean half_sitting?"),
    ],
)
def test_close_names_in_errors(path, value, expected):
    assert expected in _error(_edited(**{path: value}))


def test_no_hint_when_nothing_is_close():
    message = _error(_edited(contacts__0__surface="ceiling"))
    assert "did you mean" not in message and "known surfaces: ground" in message


names = st.text(string.ascii_lowercase + "_", min_size=5, max_size=14)


@settings(max_examples=80, deadline=None)
@given(known=st.lists(names, min_size=1, max_size=12, unique=True), data=st.data())
def test_a_name_one_typo_away_is_suggested(known, data):
    """Dropping, doubling or changing one letter of a known name: the name is suggested."""
    target = data.draw(st.sampled_from(known))
    i = data.draw(st.integers(0, len(target) - 1))
    typo = data.draw(
        st.sampled_from(
            [
                target[:i] + target[i + 1 :],
                target[:i] + target[i] + target[i:],
                target[:i] + ("x" if target[i] != "x" else "y") + target[i + 1 :],
            ]
        )
    )
    hints = close_names(typo, known)
    assert len(hints) <= 3 and set(hints) <= set(known) and typo not in hints
    if typo not in known and sum(typo in k or k in typo for k in known) <= 3:
        assert target in hints or len(hints) == 3
    assert (did_you_mean(typo, known) == "") == (hints == [])


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"contacts__0__yaw": 90}, r"contacts\[0\]\.yaw: 90 rad is more than a turn"),
        ({"surfaces__0__rpy": [0, 0, 180]}, r"surfaces\[0\]\.rpy\[2\]: 180 rad"),
        ({"tasks__0__rpy": [0, -90, 0]}, r"tasks\[0\]\.rpy\[1\]: -90 rad"),
        (
            {"surfaces__0__vertices": [[-1000, -1000], [1000, -1000], [1000, 1000], [-1000, 1000]]},
            r"surfaces\[0\]\.vertices: the surface is 2000 m across \(millimetres\?",
        ),
        (
            {"obstacles": [{"name": "box", "box": [200, 0.2, 0.2], "position": [5, 0, 0]}]},
            r"obstacles\[0\]\.box: the box is 200 m across",
        ),
        ({"tasks__0__target": [450, -350, 900]}, r"tasks\[0\]\.target: .*millimetres\?"),
        ({"tasks__0__target": [3.0, -0.35, 0.9]}, r"farther than gripper_right_base_link"),
    ],
)
def test_implausible_values_warn_and_the_problem_is_built(changes, match):
    with pytest.warns(ImplausibleValueWarning, match=match):
        problem = problem_from_dict(_edited(**changes))
    assert problem.robot.name == "talos"


def test_yaw_range_in_degrees_warns():
    data = _edited()
    data["contacts"][1] = {
        "robot_patch": "right_sole",
        "surface": "ground",
        "type": "support",
        "yaw_range": [80, 85],
    }
    with pytest.warns(
        ImplausibleValueWarning, match=r"contacts\[1\]\.yaw_range\[[01]\]: 8[05] rad"
    ):
        problem_from_dict(data)


def test_plausible_values_do_not_warn():
    problem_from_dict(_edited(contacts__0__yaw=6.2, tasks__0__target=[1.5, -0.35, 0.9]))


def test_cli_prints_a_warning_as_one_line_and_solves(tmp_path, capsys):
    problem = tmp_path / "problem.yaml"
    big = [[-1000, -1000], [1000, -1000], [1000, 1000], [-1000, 1000]]
    problem.write_text(yaml.safe_dump(_edited(surfaces__0__vertices=big)))
    assert main(["solve", str(problem), "--out", str(tmp_path), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "posturegen: warning: surfaces[0].vertices: the surface is 2000 m across "
        "(millimetres? lengths are in m)"
    ]


@pytest.mark.parametrize("robot", ["talos", "atlas"])
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_chain_length_bounds_the_distance_of_two_joints(robot, seed):
    """For random configurations within the limits, every pair of joint origins is at most
    chain_length apart."""
    model = load_bundled(robot).model
    rng = np.random.default_rng(seed)
    pin.seed(seed)  # pinocchio's randomConfiguration draws from its own generator
    q = pin.randomConfiguration(model)
    q[:3] = rng.normal(size=3)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    joints = rng.choice(np.arange(1, model.njoints), size=(10, 2))
    for a, b in joints:
        d = np.linalg.norm(data.oMi[int(a)].translation - data.oMi[int(b)].translation)
        assert d <= chain_length(model, int(a), int(b)) + 1e-9


def test_a_name_looked_up_among_none_known_is_a_one_line_input_error() -> None:
    """A contact on a surface, in a scene that has none: the error names the field, not a
    difflib ValueError (get_close_matches refuses n = 0)."""
    assert close_names("ground", []) == []
    data = {
        "robot": "talos",
        "contacts": [{"robot_patch": "left_sole", "surface": "ground", "type": "fixed"}],
    }
    message = _error(data)
    assert message.startswith("contacts[0].surface") and "\n" not in message
