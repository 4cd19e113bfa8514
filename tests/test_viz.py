"""Pictures of postures: the paper-style PNG (size, colours, time), the CLI hooks, the sequence
file, and the HTML viewer loaded offline in a real headless browser (Debian's ``chromium``)."""

from __future__ import annotations

import io
import json
import os
import shutil
import time

import numpy as np
import pytest
from PIL import Image

from posturegen import viz
from posturegen.cli import main
from posturegen.errors import InputError
from posturegen.viz import scene, view3d

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    # WebGL without a GPU: ANGLE on SwiftShader (software), which chromium only allows for
    # WebGL with this flag (else a deprecation warning now, no WebGL later)
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Two posture files drawn by the CLI's --png: the stand-reach demo (a problem file) and
    the wall-brace scene on Talos (a sequence: its left hand is a support contact on the wall,
    with an ellipse and forces on its boundary); and a sequence file of both."""
    d = tmp_path_factory.mktemp("viz")
    assert main(["demo", "stand-reach", "--out", str(d / "demo"), "--png", "--quiet"]) == 0
    brace = d / "brace"
    args = ["demo", "wall-brace", "--robot", "talos", "--out", str(brace), "--png", "--quiet"]
    assert main(args) == 0
    seq = viz.write_sequence(
        d / "sequence.json",
        [
            {"name": "stand and reach", "posture": d / "demo" / "posture.json"},
            {"name": "left hand on the wall", "posture": brace / "posture.json"},
        ],
    )
    return {"dir": d, "demo": d / "demo" / "posture.json", "brace": brace, "sequence": seq}


def _distinct(rgb: np.ndarray) -> int:
    """Number of distinct colours of an (h, w, 3) image."""
    a = rgb.reshape(-1, 3).astype(np.int64)
    return len(np.unique((a[:, 0] << 16) | (a[:, 1] << 8) | a[:, 2]))


def _colour_counts(img: Image.Image) -> dict[str, int]:
    a = np.asarray(img.convert("RGB")).astype(int)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return {
        "red": int(((r > 170) & (g < 90) & (b < 90)).sum()),
        "green": int(((g > 120) & (r < 90) & (b < 110)).sum()),
        "blue": int(((b > 150) & (r < 100) & (g < 120)).sum()),
        "distinct": _distinct(a),
    }


def test_png_has_the_papers_colours_and_size(files, tmp_path):
    # the meshes are loaded by now (the fixture's demo --png): this times the drawing
    t0 = time.perf_counter()
    out = viz.render_png(files["brace"] / "posture.json", tmp_path / "brace.png")
    elapsed = time.perf_counter() - t0
    assert elapsed < 5.0, f"render took {elapsed:.1f} s"
    img = Image.open(out)
    assert img.size[0] >= 1200 and img.size[1] >= 800
    counts = _colour_counts(img)
    assert counts["distinct"] > 200, counts
    # surface polygons and forces red, robot patches green, the support contact's ellipse blue
    assert counts["red"] > 300 and counts["green"] > 300 and counts["blue"] > 300, counts


def test_demo_png_option_and_render_command(files, tmp_path, capsys):
    png = files["demo"].with_suffix(".png")  # demo --png: next to the posture
    assert png.is_file() and Image.open(png).size == (1600, 900)
    # a scene's demo: every stage's figure beside its posture, the last one as posture.png
    stages = json.loads((files["brace"] / "sequence.json").read_text())["stages"]
    for stage in stages:
        assert (files["brace"] / stage["posture"]).with_suffix(".png").is_file()
    assert (files["brace"] / "posture.png").is_file()
    out = tmp_path / "collision.png"
    args = ["--meshes", "collision", "--azimuth", "90", "--elevation", "30"]
    assert main(["render", str(files["demo"]), "-o", str(out), *args]) == 0
    assert out.is_file()
    assert main(["render", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file" in err[0]


def test_render_accepts_a_posture_dict(files, tmp_path):
    posture = json.loads((files["brace"] / "posture.json").read_text())
    assert viz.render_png(posture, tmp_path / "p.png").is_file()
    with pytest.raises(InputError, match="schema"):
        viz.render_png({"q": []}, tmp_path / "bad.png")


def test_sequence_file_round_trip(files, tmp_path):
    stages = viz.load_sequence(files["sequence"])
    assert [name for name, _, _ in stages] == ["stand and reach", "left hand on the wall"]
    data = json.loads(files["sequence"].read_text())
    assert data["schema"] == viz.SEQUENCE_SCHEMA
    assert data["stages"][1]["posture"] == "brace/posture.json"  # relative to the sequence
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"schema": viz.SEQUENCE_SCHEMA, "stages": [{"name": "x"}]}))
    assert main(["view", str(bad), "-o", str(tmp_path / "bad.html")]) == 2


def test_decimation_keeps_the_shape():
    # a finely tessellated unit square (two triangles per 1 cm cell)
    n = 101
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    T = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    W, S = viz.decimate(V, T, 0.1)
    assert len(S) < len(T) / 50
    assert np.allclose(W.min(axis=0)[:2], 0, atol=0.06)
    assert np.allclose(W.max(axis=0)[:2], 1, atol=0.06)
    assert S.max() < len(W)


def test_zbuffer_keeps_the_nearest_triangle():
    # two 10 x 10 pixel right triangles over one square, the second nearer; a third one
    # nearer still but outside the image
    P = np.array(
        [
            [[0, 0], [10, 0], [0, 10]],
            [[0, 0], [10, 0], [0, 10]],
            [[20, 20], [30, 20], [20, 30]],
        ],
        dtype=float,
    )
    Z = np.array([[1.0, 1.0, 1.0], [2.0, 0.0, 0.0], [-5.0, -5.0, -5.0]])
    zbuf, ids = viz.rasterize(P, Z, 12, 12)
    assert (ids >= 0).sum() in range(45, 56)  # half of the 10 x 10 square
    assert ids[0, 8] == 1 and ids[8, 0] == 1  # the second one is nearer at the far corners
    assert ids[0, 0] == 0  # ... but not at the first corner (depth 2 > 1)
    assert np.isinf(zbuf[11, 11]) and ids[11, 11] == -1
    assert np.isclose(zbuf[0, 0], 1.0)


def test_camera_keeps_the_contacts_in_view(files):
    # the brace posture: the wall's side of the robot faces the chosen camera, and every
    # contact and force point is inside the figure's window
    posture = viz.load_posture_any(files["brace"] / "posture.json")
    sv = viz.stance_view(posture)
    robot = sv.world_triangles()
    content = scene.content_points(sv, robot, scene.force_scale([sv]))
    cam = view3d.choose_camera(sv, robot, scene.scene_mesh(sv)[0], content, viz.VIEW_ELEVATION)
    wall = next(c for c in sv.contacts if c.surface == "wall")
    assert wall.T_ws[:3, 2] @ -cam.forward > 0
    frame = viz.Frame.fit(cam.screen(content), 800, 700)
    for c in sv.contacts:
        px = frame.pixels(cam.screen(np.vstack([c.patch3d, c.points3d])))
        assert (px >= 0).all() and (px[:, 0] < 800).all() and (px[:, 1] < 700).all()


def test_html_is_one_offline_file(files, tmp_path):
    out = viz.write_html(files["sequence"], tmp_path / "seq.html")
    text = out.read_text()
    size_mb = out.stat().st_size / 1e6
    assert size_mb < 5, f"{size_mb:.1f} MB"
    assert "<script src" not in text and "<link" not in text
    assert text.count("</script>") == 4  # three.js, OrbitControls, data, the viewer


def _no_browser(reason: str) -> None:
    """Skip for ``reason`` (what is missing and how to install it), or fail with it when CI
    requires the browser test (``.ci/run`` sets the variable)."""
    if os.environ.get("POSTUREGEN_REQUIRE_BROWSER") == "1":
        pytest.fail(reason)
    pytest.skip(reason=reason)


@pytest.fixture
def browser():
    """Chromium's path and playwright's entry point (before the postures are solved)."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        _no_browser("no chromium: install the Debian package 'chromium' (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _no_browser("playwright is not installed (pip install -e '.[test]')")
    return chromium, sync_playwright


def test_viewer_draws_in_headless_chromium(browser, files, tmp_path):
    chromium, sync_playwright = browser
    html = viz.write_html(files["sequence"], tmp_path / "seq.html")
    messages, requests = [], []
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"),  # a fresh user-data-dir
            executable_path=chromium,
            args=CHROMIUM_FLAGS,
            viewport={"width": 1000, "height": 700},
        )
        try:
            context.set_offline(True)
            page = context.new_page()
            page.on("console", lambda m: messages.append((m.type, m.text)))
            page.on("pageerror", lambda e: messages.append(("pageerror", str(e))))
            page.on("request", lambda r: requests.append(r.url))
            page.goto(html.as_uri())
            page.wait_for_function(
                "(window.posturegenViewer && window.posturegenViewer.ready)"
                " || !document.getElementById('error').hidden",
                timeout=30_000,
            )
            assert page.evaluate("document.getElementById('error').hidden"), page.inner_text(
                "#error"
            )
            _assert_panel_beside_the_robot(page)
            first = Image.open(io.BytesIO(page.locator("canvas").screenshot()))
            # the slider moves to the second stance; a toggle hides the forces
            page.evaluate(
                "const s = document.getElementById('stage'); s.value = '1';"
                "s.dispatchEvent(new Event('input'))"
            )
            label = page.inner_text("#stage-label")
            page.click("#show-forces")
            second = Image.open(io.BytesIO(page.locator("canvas").screenshot()))
        finally:
            context.close()
    errors = [m for m in messages if m[0] in ("error", "pageerror")]
    assert not errors, errors
    schemes = {u.split(":", 1)[0] for u in requests}
    assert schemes <= {"file", "blob", "data"}, requests
    a = np.asarray(first.convert("RGB"))
    assert _distinct(a) > 50  # not blank: shaded meshes
    assert (a.std(axis=(0, 1)) > 5).all()
    assert "2/2" in label and "left hand on the wall" in label
    assert not np.array_equal(a, np.asarray(second.convert("RGB")))


def _assert_panel_beside_the_robot(page) -> None:
    """The control panel does not cover the canvas, and the robot (its mesh vertices projected
    by the viewer's camera) is inside the canvas."""
    panel, canvas, robot = page.evaluate(
        "[document.getElementById('panel').getBoundingClientRect().toJSON(),"
        " document.querySelector('canvas').getBoundingClientRect().toJSON(),"
        " window.posturegenViewer.robotScreenBox()]"
    )
    apart = (
        panel["right"] <= canvas["left"]
        or canvas["right"] <= panel["left"]
        or panel["bottom"] <= canvas["top"]
        or canvas["bottom"] <= panel["top"]
    )
    assert apart, (panel, canvas)
    viewport = page.viewport_size
    assert (
        canvas["right"] <= viewport["width"] + 0.5 and canvas["bottom"] <= viewport["height"] + 0.5
    )
    for a, b in (("left", "right"), ("top", "bottom")):
        assert canvas[a] <= robot[a] < robot[b] <= canvas[b], (robot, canvas)


@pytest.mark.parametrize("viewport", [(1400, 700), (600, 800), (700, 420)])
def test_viewer_panel_is_beside_the_robot(browser, files, tmp_path, viewport):
    # wide, narrow (the panel above the view) and small windows
    chromium, sync_playwright = browser
    html = viz.write_html(files["demo"], tmp_path / "demo.html")
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path / "profile"),
            executable_path=chromium,
            args=CHROMIUM_FLAGS,
            viewport={"width": viewport[0], "height": viewport[1]},
        )
        try:
            context.set_offline(True)
            page = context.new_page()
            page.goto(html.as_uri())
            page.wait_for_function("window.posturegenViewer && window.posturegenViewer.ready")
            _assert_panel_beside_the_robot(page)
        finally:
            context.close()
