"""Figures a user can read: obstacles drawn at their depth (an arm in front of a box keeps its
colour), the world axes and a scale bar in the 3-D view, labels that never overlap."""

from __future__ import annotations

import copy
import itertools
import json
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

from posturegen import viz
from posturegen.cli import main
from posturegen.viz import closeup, labels, scene, triad, view3d
from posturegen.viz.raster import Frame, rasterize
from posturegen.viz.views import ContactView, lift


@pytest.fixture(scope="module")
def posture(tmp_path_factory):
    """The stand-reach demo's posture (Talos on both feet, the right gripper at a target)."""
    d = tmp_path_factory.mktemp("readable")
    assert main(["demo", "stand-reach", "--out", str(d), "--quiet"]) == 0
    return json.loads((d / "posture.json").read_text())


def _box_behind_the_hand(posture: dict, cam: viz.Camera) -> dict:
    """The posture with a 0.3 m box 0.35 m behind the right gripper's target, seen from
    ``cam``: the arm is in front of it."""
    target = np.asarray(posture["tasks"][0]["target"], dtype=float)
    T = np.eye(4)
    T[:3, :3] = np.array([[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])  # a yawed box
    T[:3, 3] = target + 0.35 * cam.forward
    out = copy.deepcopy(posture)
    out["obstacles"] = [{"name": "box", "box": {"size": [0.3, 0.3, 0.3], "placement": T.tolist()}}]
    return out


def _view_pixels(posture: dict, azimuth: float, size=(800, 700)) -> tuple[np.ndarray, object]:
    """The 3-D view alone on a figure it fills: its RGB pixels (h, w, 3) and the Triad."""
    sv = viz.stance_view(posture)
    view = view3d.View3D.of(sv, scene.force_scale([sv]), azimuth)
    fig = Figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    drawn = view3d.draw_3d(ax, view, *size)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(float) / 255, drawn


def _depth(cam, frame: Frame, tris: np.ndarray) -> np.ndarray:
    return rasterize(frame.pixels(cam.screen(tris)), cam.depth(tris), frame.width, frame.height)[0]


def _every(mask: np.ndarray, k: int = view3d.SUPERSAMPLE) -> np.ndarray:
    """A supersampled mask reduced to the pixels whose k x k samples are all set."""
    h, w = mask.shape
    return mask.reshape(h // k, k, w // k, k).all(axis=(1, 3))


def _erode(mask: np.ndarray, n: int) -> np.ndarray:
    out = mask.copy()
    for _ in range(n):
        out[1:] &= out[:-1].copy()
        out[:-1] &= out[1:].copy()
        out[:, 1:] &= out[:, :-1].copy()
        out[:, :-1] &= out[:, 1:].copy()
    return out


def _outside(box: labels.Box, shape: tuple[int, int]) -> np.ndarray:
    """Pixels (image rows down) outside a display box (y up) of a figure of ``shape``."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w]
    y = h - 1 - y
    return ~((x >= box.x0 - 2) & (x <= box.x1 + 2) & (y >= box.y0 - 2) & (y <= box.y1 + 2))


def test_an_arm_in_front_of_a_box_keeps_the_robots_colour(posture):
    azimuth = -35.0
    cam = view3d.View3D.of(viz.stance_view(posture), 0.0, azimuth).cam
    boxed = _box_behind_the_hand(posture, cam)
    with_box, t1 = _view_pixels(boxed, azimuth)
    without, t2 = _view_pixels(posture, azimuth)
    # where the robot is nearer than the box, in the figure's own window
    sv = viz.stance_view(boxed)
    view = view3d.View3D.of(sv, scene.force_scale([sv]), azimuth)
    frame = Frame.fit(cam.screen(view.content), 800, 700, margin=0.03)
    big = frame.scaled(view3d.SUPERSAMPLE)  # as the image is drawn, then averaged
    robot_z, box_z = _depth(cam, big, view.robot), _depth(cam, big, view.scene[2])
    robot_front = _erode(_every(np.isfinite(box_z) & (robot_z < box_z)), 1)
    box_front = _erode(_every(np.isfinite(box_z) & (box_z < robot_z)), 1)
    keep = _outside(t1.card, robot_front.shape) & _outside(t2.card, robot_front.shape)
    robot_front &= keep
    assert robot_front.sum() > 300, "the arm is not in front of the box: the test shows nothing"
    diff = np.abs(with_box - without).max(axis=-1)
    assert diff[robot_front].max() <= 2 / 255, "the box is drawn over the arm in front of it"
    assert np.mean(diff[box_front & keep] > 2 / 255) > 0.95  # the box drawn where nearest


def _tip_ratio(drawing_triad, cam, name: str) -> tuple[float, float]:
    d = cam.screen(np.eye(3)["xyz".index(name)])
    v = drawing_triad.tips[name] - drawing_triad.origin
    return float(np.dot(v, d) / (np.linalg.norm(v) * np.linalg.norm(d))), float(np.linalg.norm(d))


def test_the_view_has_world_axes_and_a_scale_bar(posture):
    drawing = viz.draw_figure(posture, azimuth=-35.0)
    fig, cam = drawing.figure, drawing.view.cam
    fig.canvas.draw()
    ax3 = fig.axes[0]
    arrows = {a.get_gid(): a for a in ax3.texts if (a.get_gid() or "").startswith("world-axis-")}
    letters = {a.get_text() for g, a in arrows.items() if g.startswith("world-axis-label-")}
    assert letters == {"x", "y", "z"}
    for name in "xyz":
        arrow = arrows.get(f"world-axis-{name}")
        cos, n = _tip_ratio(drawing.triad, cam, name)
        if n > 0.2:  # drawn as an arrow: along the axis' projection, as long as it
            assert arrow is not None and np.allclose(arrow.xy, drawing.triad.tips[name])
            assert np.allclose(arrow.xyann, drawing.triad.origin)
            assert cos > 1 - 1e-9
    up = drawing.triad.tips["z"] - drawing.triad.origin
    assert up[1] > 0.9 * np.linalg.norm(up)  # z points up the screen at 18° elevation
    (bar,) = [line for line in ax3.lines if line.get_gid() == "scale-bar"]
    (label,) = [t for t in ax3.texts if t.get_gid() == "scale-label"]
    value, unit = re.fullmatch(r"([\d.]+) (cm|m)", label.get_text()).groups()
    metres = float(value) * (0.01 if unit == "cm" else 1.0)
    xs, ys = bar.get_xdata(), bar.get_ydata()
    assert ys[0] == ys[1] and abs(abs(xs[1] - xs[0]) - metres) < 1e-12  # screen metres
    # the card inside the view, and no contact label over it
    renderer = fig.canvas.get_renderer()
    assert drawing.triad.card.inside(labels.Box.of(ax3.get_window_extent(renderer)))
    names = [t for t in ax3.texts if t.get_gid() == "contact-label"]
    assert len(names) == 2
    assert not any(b.meets(drawing.triad.card) for b in labels.text_boxes(names, renderer))


def test_a_scale_bars_label():
    assert triad.scale_text(0.2) == "20 cm" and triad.scale_text(1.0) == "1 m"
    assert triad.scale_text(0.25) == "25 cm" and triad.scale_text(2.0) == "2 m"


def _assert_apart(boxes: list[labels.Box]) -> None:
    for a, b in itertools.combinations(boxes, 2):
        assert not a.meets(b), (a, b)


def test_no_two_labels_of_a_figure_overlap(posture):
    # both feet's force labels, the contacts' names, the axes' letters and the scale's label
    drawing = viz.draw_figure(posture)
    fig = drawing.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    texts = [
        t
        for ax in fig.axes
        for t in ax.texts
        if t.get_gid() in ("force-label", "contact-label", "scale-label")
        or (t.get_gid() or "").startswith("world-axis-label")
    ]
    forces = [t for t in texts if t.get_gid() == "force-label"]
    assert len(forces) == 8  # every vertex of both feet labelled
    _assert_apart(labels.text_boxes(texts, renderer))


@st.composite
def crowded_contacts(draw):
    """A contact whose force points crowd within a few cm: n points (2-10) of random normal
    forces, around a random centre of a large surface."""
    n = draw(st.integers(2, 10))
    spread = draw(st.floats(0.002, 0.05))
    xy = (
        np.array(draw(st.lists(st.tuples(*[st.floats(-1, 1)] * 2), min_size=n, max_size=n)))
        * spread
    )
    fn = np.array(draw(st.lists(st.floats(5, 500), min_size=n, max_size=n)))
    ft = np.array(draw(st.lists(st.tuples(*[st.floats(-0.5, 0.5)] * 2), min_size=n, max_size=n)))
    pts3 = lift(xy)
    forces = np.column_stack([ft * fn[:, None], fn])
    patch = np.array([[-0.1, -0.06], [0.1, -0.06], [0.1, 0.06], [-0.1, 0.06]])
    return ContactView(
        name="c",
        type="fixed",
        surface="s",
        T_ws=np.eye(4),
        surface2d=np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]),
        patch2d=patch,
        patch3d=lift(patch),
        points3d=pts3,
        forces3d=forces,
    )


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(crowded_contacts(), st.sampled_from([(3.4, 2.8), (5.2, 3.4), (2.6, 2.0)]))
def test_crowded_force_labels_never_overlap(c, size):
    # a close-up cell of the figure's sizes (four contacts, two, and a small one)
    fig = Figure(figsize=size, dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.15, 0.15, 0.8, 0.7))
    closeup.draw_closeup(ax, c, 0.0)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    drawn = [t for t in ax.texts if t.get_gid() == "force-label"]
    fn = c.forces3d[:, 2]
    wanted = int(np.sum(fn > max(0.05 * fn.max(), 0.5)))
    assert len(drawn) == wanted  # every label found a place
    boxes = labels.text_boxes(drawn, renderer)
    _assert_apart(boxes)
    frame = labels.Box.of(ax.get_window_extent(renderer))
    assert all(b.inside(frame) for b in boxes)
    # and none over a force point's marker
    centres = ax.transData.transform(c.to_surface(c.points3d))
    for b in boxes:
        inside = (centres[:, 0] > b.x0) & (centres[:, 0] < b.x1)
        inside &= (centres[:, 1] > b.y0) & (centres[:, 1] < b.y1)
        assert not inside.any()


def test_labels_are_placed_on_their_side_when_it_is_free():
    fig = Figure(figsize=(4, 3), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 4)
    ax.set_ylim(0, 3)
    (a,) = labels.place_labels(ax, np.array([[2.0, 1.5]]), ["12 N"], np.array([[1.0, 0.0]]))
    fig.canvas.draw()
    box = labels.text_boxes([a], fig.canvas.get_renderer())[0]
    x, y = ax.transData.transform((2.0, 1.5))
    assert box.x0 > x and box.y0 < y < box.y1  # to the right, level with its point
    assert isinstance(a, Text)
