"""simbake preview and simbake report: pixels where the camera maps things, movies read back.

The test stage is written here with pxr: a box mesh, two one-sided quads of a double-sided
(cloth) mesh, one facing the camera and one facing away, a camera prim and a ground height.
Where each thing lands in the picture is computed here with a pinhole projection of the
camera's focal length and apertures (chosen with the picture's aspect, so no fitting is
involved), not with the renderer's matrices.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import BOXES_ONE_CM_DEEP

import numpy as np
import pytest

W, H = 320, 180
FOCAL, H_APERTURE, V_APERTURE = 30.0, 32.0, 18.0  # mm; 32:18 = 16:9 = W:H
CAMERA_AT = np.array([0.0, 1.0, 6.0])             # looking down -z (USD's camera convention)
BOX_CENTER, BOX_SIZE = np.array([-1.2, 0.5, 0.0]), 1.0


def project(point, camera_at=CAMERA_AT, down: bool = False, size=(W, H)) -> tuple[int, int]:
    """Pixel (column, row from the top) of a world point seen by the test camera (at
    `camera_at`, looking down -z; or, `down`, turned -90 degrees about x: looking down -y
    with its picture's up along -z)."""
    x, y, z = np.asarray(point, dtype=float) - camera_at
    if down:
        y, z = -z, y
    u = (FOCAL * x / -z) / (H_APERTURE / 2)  # -1..1 across the picture
    v = (FOCAL * y / -z) / (V_APERTURE / 2)
    return int(round((u + 1) / 2 * size[0])), int(round((1 - v) / 2 * size[1]))


def write_stage(path: Path, frames: int = 3, fps: float = 24.0) -> Path:
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(frames)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.GetRootLayer().customLayerData = {"simbake": {"ground": {"height": 0.0}}}
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    # a box: a closed mesh of six quads, outward, moving up 1 cm a frame
    body = UsdGeom.Xform.Define(stage, "/World/box")
    translate = body.AddTranslateOp()
    for f in range(1, frames + 1):
        translate.Set(Gf.Vec3d(*(BOX_CENTER + [0, 0.01 * (f - 1), 0])), f)
    h = BOX_SIZE / 2
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = UsdGeom.Mesh.Define(stage, "/World/box/mesh")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*c) for c in corners]))
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    # the cloth: two quads in the plane z = 0, the left one wound towards the camera (front),
    # the right one away from it (back)
    cloth = UsdGeom.Mesh.Define(stage, "/World/sheet")
    pts = [(0.4, 0.2, 0), (1.0, 0.2, 0), (1.0, 0.8, 0), (0.4, 0.8, 0),
           (1.4, 0.2, 0), (2.0, 0.2, 0), (2.0, 0.8, 0), (1.4, 0.8, 0)]
    cloth.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    cloth.CreateFaceVertexCountsAttr([4, 4])
    cloth.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 7, 6, 5, 4])
    cloth.CreateDoubleSidedAttr(True)
    cloth.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    camera = UsdGeom.Camera.Define(stage, "/World/camera")
    camera.AddTranslateOp().Set(Gf.Vec3d(*CAMERA_AT))
    camera.CreateFocalLengthAttr(FOCAL)
    camera.CreateHorizontalApertureAttr(H_APERTURE)
    camera.CreateVerticalApertureAttr(V_APERTURE)
    camera.CreateClippingRangeAttr(Gf.Vec2f(0.1, 100.0))
    stage.GetRootLayer().Save()
    return path


def render(path: Path, frames: str = "1", camera: str = "/World/camera", size=(W, H)) -> np.ndarray:
    from simbake.preview import Preview, parse_frames

    preview = Preview(path, size, camera)
    try:
        chosen = parse_frames(frames, preview.start, preview.end, None)
        return [image for _, image in preview.frames(chosen)][0]
    finally:
        preview.close()


def is_grey(pixel) -> bool:
    p = pixel.astype(int)
    return p.max() - p.min() < 12


def test_things_are_where_the_camera_maps_them(tmp_path):
    from simbake.preview import SKY

    image = render(write_stage(tmp_path / "stage.usda"))
    assert image.shape == (H, W, 3)
    # the box's front face (z = +0.5, facing the camera), at its centre: the box's own colour,
    # neither sky nor ground
    col, row = project(BOX_CENTER + [0, 0, BOX_SIZE / 2])
    box = image[row, col]
    assert not is_grey(box), box
    # the ground in front of the box (lit or in shadow, its checks are grey) and the sky above
    col, row = project([-1.2, 0.0, 2.5])
    assert is_grey(image[row, col]) and image[row, col].min() > 60, image[row, col]
    sky = np.round(np.array(SKY) * 255)
    col, row = project([0.0, 2.6, 0.0])
    assert np.abs(image[row, col].astype(int) - sky).max() <= 3, image[row, col]
    # what is just beside the box is not the box
    col, row = project(BOX_CENTER + [-BOX_SIZE, 0, 0])
    assert np.abs(image[row, col].astype(int) - box.astype(int)).max() > 20


def test_cloth_front_and_back_show_in_their_colours(tmp_path):
    image = render(write_stage(tmp_path / "stage.usda"))
    front = image[project([0.7, 0.5, 0.0])[::-1]].astype(int)
    back = image[project([1.7, 0.5, 0.0])[::-1]].astype(int)
    assert front[0] > front[1] > front[2] and front[0] - front[2] > 60, front  # orange
    assert back[2] > back[1] > back[0] and back[2] - back[0] > 60, back        # blue


def test_frame_label_is_burned_in(tmp_path):
    stage = write_stage(tmp_path / "stage.usda")
    labelled = render(stage, frames="2")
    from simbake.preview import Preview

    preview = Preview(stage, (W, H), "/World/camera")
    try:
        bare = next(iter(preview.frames([2], label=False)))[1]
    finally:
        preview.close()
    corner = labelled[: H // 6, : W // 2].astype(int)
    assert (corner.min(axis=2) > 230).sum() > 30   # white text
    assert (corner.max(axis=2) < 40).sum() > 200   # on its dark box
    # the label is the only difference: the rest of the picture is the same
    assert np.array_equal(labelled[H // 4:], bare[H // 4:])
    assert not np.array_equal(labelled[: H // 6, : W // 2], bare[: H // 6, : W // 2])


def test_automatic_camera_sees_the_whole_animation(tmp_path):
    from simbake.preview import Preview, auto_camera

    stage = write_stage(tmp_path / "stage.usda")
    preview = Preview(stage, (W, H))
    lo, hi, _, _ = preview.frame_range([1, 2, 3])
    cam = auto_camera(lo, hi, W / H)
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    clip = corners @ (cam.projection @ cam.view).T
    ndc = clip[:, :3] / clip[:, 3:]
    assert (np.abs(ndc[:, :2]) <= 1.0).all()          # every corner inside the picture
    assert np.abs(ndc[:, :2]).max() > 0.8              # and the box fills it
    preview.close()


def test_movie_has_every_frame_at_the_cache_rate(tmp_path):
    import imageio.v3 as iio
    import imageio_ffmpeg

    from simbake.preview import write_preview

    stage = write_stage(tmp_path / "stage.usda", frames=12, fps=12.0)
    out, count = write_preview(stage, tmp_path / "movie.mp4", size=(160, 90))
    assert count == 12
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == 12 and seconds == pytest.approx(1.0, abs=0.05)
    assert iio.immeta(out)["fps"] == pytest.approx(12.0)
    first = next(iter(iio.imiter(out)))
    assert first.shape == (90, 160, 3)
    # every other frame: half the rate
    out, count = write_preview(stage, tmp_path / "half.gif", frames="1:12:2", size=(160, 90))
    assert count == 6
    gif = list(iio.imiter(out))
    assert len(gif) == 6
    assert iio.immeta(out, index=0)["duration"] == pytest.approx(1000 / 6, abs=10)  # ms per frame


def test_contact_sheet_holds_eight_evenly_spaced_frames(tmp_path):
    from PIL import Image

    from simbake.preview import parse_frames, write_preview

    assert parse_frames(None, 1, 97, 8) == [1, 15, 28, 42, 56, 70, 83, 97]
    assert parse_frames("10:20:5", 1, 97, 8) == [10, 15, 20]
    stage = write_stage(tmp_path / "stage.usda", frames=20)
    out, count = write_preview(stage, tmp_path / "sheet.png", size=(100, 60))
    assert count == 8
    assert Image.open(out).size == (4 * 100 + 5 * 4, 2 * 60 + 3 * 4)


def run(*args, cwd: Path):
    return subprocess.run([sys.executable, "-m", "simbake", *args], cwd=cwd, capture_output=True, text=True)


@pytest.mark.parametrize("args, problem", [
    (["missing.usdc"], "no such file"),
    (["stage.usda", "--frames", "5:1"], "--frames"),
    (["stage.usda", "--frames", "x"], "--frames"),
    (["stage.usda", "--camera", "/World/box"], "not a Camera prim"),
    (["stage.usda", "--size", "10x10"], "--size"),
    (["stage.usda", "-o", "out.jpg"], "output must end in"),
])
def test_bad_preview_arguments_are_one_line_errors(tmp_path, args, problem):
    write_stage(tmp_path / "stage.usda")
    result = run("preview", *args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("simbake: error:") and problem in lines[0], result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stage.usda"]


def test_bake_with_preview_writes_movie_and_report(write_scene, tmp_path):
    path = write_scene("""
        [scene]
        end_frame = 6
        [ground]
        [[bodies]]
        name = "ball"
        shape = { type = "sphere", radius = 0.2 }
        position = [0.0, 1.0, 0.0]
        [[cloths]]
        name = "sheet"
        grid = { size = [1.0, 1.0], resolution = [5, 5] }
        position = [0.0, 2.0, 0.0]
    """)
    result = run("bake", str(path), "-o", "shot.usdc", "--preview", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["scene.toml", "shot.mp4", "shot.qa.json", "shot.report.html", "shot.usdc"]
    page = (tmp_path / "shot.report.html").read_text()
    assert "clean: no figure over its threshold" in page and "data:image/png;base64," in page
    # the report as a picture too
    result = run("report", "shot.usdc", "-o", "page.png", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "page.png").read_bytes().startswith(b"\x89PNG")


def test_report_names_the_warnings_and_needs_its_qa_data(write_scene, tmp_path):
    path = write_scene(BOXES_ONE_CM_DEEP)
    assert run("bake", str(path), "-o", "x.usdc", "-q", cwd=tmp_path).returncode == 0
    assert run("report", "x.usdc", cwd=tmp_path).returncode == 0
    page = (tmp_path / "x.report.html").read_text()
    assert "1 warning(s)" in page and "deepest body penetration 10 mm (b into a) at frame 1" in page
    (tmp_path / "x.qa.json").unlink()
    result = run("report", "x.usdc", cwd=tmp_path)
    assert result.returncode == 2 and "x.qa.json is missing" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_point_instancer_draws_each_instance_where_it_is(tmp_path):
    # two instances of a unit cube prototype (its root moved up 0.5 m, included in the
    # instance transforms), at x = -1.2 and x = +1.2: both show where the camera maps them,
    # and nothing between them
    from pxr import Gf, Usd, UsdGeom, Vt

    path = tmp_path / "instanced.usda"
    stage = Usd.Stage.Open(str(write_stage(path)))
    stage.RemovePrim("/World/box")
    stage.RemovePrim("/World/sheet")
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/boxes")
    proto = UsdGeom.Xform.Define(stage, "/World/boxes/prototypes/cube")
    proto.AddTranslateOp().Set(Gf.Vec3d(0, 0.5, 0))
    cube = UsdGeom.Cube.Define(stage, "/World/boxes/prototypes/cube/shape")  # drawn, inside the mesh
    cube.CreateSizeAttr(0.1)
    mesh = UsdGeom.Mesh.Define(stage, "/World/boxes/prototypes/cube/mesh")
    h = 0.5
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*c) for c in corners]))
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    instancer.CreatePrototypesRel().SetTargets([proto.GetPath()])
    instancer.CreateProtoIndicesAttr([0, 0])
    instancer.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(-1.2, 0, 0), Gf.Vec3f(1.2, 0, 0)]))
    stage.GetRootLayer().Save()
    image = render(path)
    for x in (-1.2, 1.2):
        for y in (0.15, 0.5, 0.85):  # the cube spans y 0..1 (its root's 0.5 m counted once)
            col, row = project([x, y, 0.5])
            assert not is_grey(image[row, col]), (x, y, image[row, col])
        col, row = project([x, 1.15, 0.5])
        assert is_grey(image[row, col]) or image[row, col].min() > 200
    col, row = project([0.0, 0.5, 0.0])
    assert is_grey(image[row, col]) or image[row, col].min() > 200  # ground or sky between them


def test_z_up_stage_renders_as_its_y_up_twin(tmp_path):
    # the same stage with every position turned to Z up (y -> z, z -> -y) and upAxis Z
    from pxr import Gf, Usd, UsdGeom

    y_up = render(write_stage(tmp_path / "y.usda"))
    stage = Usd.Stage.Open(str(write_stage(tmp_path / "z.usda")))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    turn = Gf.Matrix4d().SetRotate(Gf.Rotation(Gf.Vec3d(1, 0, 0), 90))
    y_stage = Usd.Stage.Open(str(tmp_path / "y.usda"))
    for path in ("/World/box", "/World/camera"):
        xform = UsdGeom.Xformable(stage.GetPrimAtPath(path))
        xform.ClearXformOpOrder()
        op = xform.AddTransformOp()
        original = y_stage.GetPrimAtPath(path)
        for t in (1.0, 2.0, 3.0):
            local = UsdGeom.Xformable(original).GetLocalTransformation(t)
            op.Set(local * turn, t)
    sheet = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    sheet.GetPointsAttr().Set([Gf.Vec3f(p[0], -p[2], p[1]) for p in sheet.GetPointsAttr().Get()])
    box_mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/box/mesh"))
    box_mesh.GetPointsAttr().Set([Gf.Vec3f(p[0], -p[2], p[1]) for p in box_mesh.GetPointsAttr().Get()])
    stage.GetRootLayer().Save()
    z_up = render(tmp_path / "z.usda")
    # the same picture, up to the rounding of the turned coordinates at a few edge pixels
    differ = np.abs(z_up.astype(int) - y_up.astype(int)).max(axis=2) > 24
    assert differ.mean() < 0.01, differ.mean()


def gprim_stage(path: Path):
    """The test stage without its box and cloth (the camera and ground stay), open for edits."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(write_stage(path)))
    stage.RemovePrim("/World/box")
    stage.RemovePrim("/World/sheet")
    return stage


def is_sky(pixel) -> bool:
    from simbake.preview import SKY

    return np.abs(pixel.astype(int) - np.round(np.array(SKY) * 255)).max() <= 3


def test_gprims_are_where_the_camera_maps_them(tmp_path):
    # a Cube (size), a Sphere (radius) and a Capsule (radius, height, axis X) standing on the
    # ground, side by side: each shows its own colour at its projected centre, sky above it
    # and ground beside it
    from pxr import Gf, UsdGeom

    path = tmp_path / "gprims.usda"
    stage = gprim_stage(path)
    cube = UsdGeom.Cube.Define(stage, "/World/cube")
    cube.CreateSizeAttr(0.8)
    cube.AddTranslateOp().Set(Gf.Vec3d(-1.8, 0.4, 0))
    sphere = UsdGeom.Sphere.Define(stage, "/World/ball")
    sphere.CreateRadiusAttr(0.4)
    sphere.AddTranslateOp().Set(Gf.Vec3d(0, 0.4, 0))
    capsule = UsdGeom.Capsule.Define(stage, "/World/pill")
    capsule.CreateRadiusAttr(0.3)
    capsule.CreateHeightAttr(0.8)  # the spine: 1.4 m long in all, x 1.1 to 2.5
    capsule.CreateAxisAttr(UsdGeom.Tokens.x)
    capsule.AddTranslateOp().Set(Gf.Vec3d(1.8, 0.3, 0))
    stage.GetRootLayer().Save()
    image = render(path)
    for center, half_x, top, front in (((-1.8, 0.4, 0), 0.4, 0.8, 0.4), ((0, 0.4, 0), 0.4, 0.8, 0.4),
                                       ((1.8, 0.3, 0), 0.7, 0.6, 0.3)):
        c = np.array(center, dtype=float)
        col, row = project(c + [0, 0, front])
        shown = image[row, col]
        assert not is_grey(shown) and not is_sky(shown), (center, shown)
        # its ends along x, just inside, are it too
        for side in (-1, 1):
            col, row = project(c + [side * (half_x - 0.08), 0, 0.2])
            assert not is_grey(image[row, col]), (center, side, image[row, col])
        col, row = project(c + [0, 0, 0] + [0, 1.6 - c[1], 0])  # above: sky
        assert is_sky(image[row, col]), (center, image[row, col])
        col, row = project([c[0], top + 0.12, front])          # just over its top: not it
        assert is_grey(image[row, col]) or is_sky(image[row, col]), (center, image[row, col])
    for x in (-0.9, 0.85):  # between them: the ground
        col, row = project([x, 0.0, 1.0])
        assert is_grey(image[row, col]) and image[row, col].min() > 60, (x, image[row, col])


def test_gprim_honours_a_scaled_and_turned_parent(tmp_path):
    # a 0.4 m Cube at (0.5, 0.2, 0) under a parent turned -90 degrees about y (x -> z), scaled 2
    # and moved 1 m along x: an 0.8 m cube at (1.0, 0.4, 1.0), standing on the ground
    from pxr import Gf, UsdGeom

    path = tmp_path / "parent.usda"
    stage = gprim_stage(path)
    parent = UsdGeom.Xform.Define(stage, "/World/parent")
    parent.AddTranslateOp().Set(Gf.Vec3d(1.0, 0, 0))
    parent.AddRotateYOp().Set(-90.0)
    parent.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    cube = UsdGeom.Cube.Define(stage, "/World/parent/cube")
    cube.CreateSizeAttr(0.4)
    cube.AddTranslateOp().Set(Gf.Vec3d(0.5, 0.2, 0))
    stage.GetRootLayer().Save()
    image = render(path)
    col, row = project([1.0, 0.4, 1.4])
    cube = image[row, col].astype(int)
    assert not is_grey(cube), cube
    for point in ([1.0, 0.72, 1.4], [0.68, 0.08, 1.4], [1.32, 0.4, 1.4]):
        col, row = project(point)
        assert np.abs(image[row, col].astype(int) - cube).max() < 20, (point, image[row, col])
    # not where the parent's turn, scale or move left out would put it (ground, sky, or the
    # ground fading into the sky far behind)
    for point in ([1.0, 0.95, 1.4], [2.0, 0.4, 0.0], [0.5, 0.2, 0.2], [0.0, 0.4, 1.0]):
        col, row = project(point)
        other = image[row, col].astype(int)
        assert is_sky(other) or other.max() - other.min() < 20, (point, other)
        assert np.abs(other - cube).max() > 30, (point, other)


def test_shot_stage_shows_every_body_on_its_plane_ground(tmp_path):
    # the shipped shot baked with --shot: every body (Cube, Sphere, Capsule gprims, the kinematic
    # pusher) shows in its own colour where its composed transform puts it, seen from straight
    # above at the first and last frames; the static block's front face shows from the front;
    # the 10 m ground Plane is the checkered ground and not what the automatic camera frames
    from pxr import Gf, Usd, UsdGeom

    from simbake.preview import Preview, _color

    shot = Path(__file__).resolve().parents[2] / "assets" / "scenes" / "shot.usda"
    result = run("bake", str(shot), "-o", "c.usdc", "--shot", "view.usda", "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    view = tmp_path / "view.usda"
    stage = Usd.Stage.Open(str(view))
    above, front = np.array([0.2, 9.0, 0.0]), np.array([2.2, 0.25, 6.0])
    for name, at, down in (("above", above, True), ("front", front, False)):
        camera = UsdGeom.Camera.Define(stage, f"/World/{name}")
        camera.AddTranslateOp().Set(Gf.Vec3d(*at))
        if down:
            camera.AddRotateXOp().Set(-90.0)
        camera.CreateFocalLengthAttr(FOCAL)
        camera.CreateHorizontalApertureAttr(H_APERTURE)
        camera.CreateVerticalApertureAttr(V_APERTURE)
        camera.CreateClippingRangeAttr(Gf.Vec2f(0.1, 100.0))
    stage.GetRootLayer().Save()
    size = (2 * W, 2 * H)

    def looks_like(image, point, path, camera_at, down):
        col, row = project(point, camera_at, down, size)
        pixel = image[row, col].astype(float)
        base = np.array(_color(path))
        cosine = pixel @ base / (np.linalg.norm(pixel) * np.linalg.norm(base))
        return cosine > 0.998 and not is_grey(image[row, col]), (path, pixel, base * 255)

    bodies = ["/World/Props/Crate", "/World/Props/Ball", "/World/Props/Pill", "/World/Pusher"]
    for name, at, down in (("above", above, True), ("front", front, False)):
        preview = Preview(view, size, f"/World/{name}")
        try:
            assert preview.geometry.ground_plane.GetPath() == "/World/Ground"
            assert preview.geometry.ground_height == pytest.approx(0.0)
            lo, hi, _, ground = preview.frame_range([preview.start, preview.end])
            assert ground == pytest.approx(0.0) and (hi - lo)[[0, 2]].max() < 6.0, (lo, hi)  # not 10 m
            for frame in (preview.start, preview.end):
                image = next(iter(preview.frames([frame], label=False)))[1]
                if not down:
                    ok, why = looks_like(image, [2.2, 0.25, 1.7], "/World/Block", at, down)
                    assert ok, (frame, why)
                    continue
                xforms = UsdGeom.XformCache(frame)
                for path in bodies:
                    center = np.array(xforms.GetLocalToWorldTransform(stage.GetPrimAtPath(path)).ExtractTranslation())
                    assert center[1] > 0.1, (path, frame, center)  # above the ground, not sunk
                    ok, why = looks_like(image, center, path, at, down)
                    assert ok, (frame, why)
        finally:
            preview.close()


def test_skinned_mesh_is_drawn_at_each_frames_pose(tmp_path):
    # a box Mesh bound with weight 1 to a one-joint Skeleton whose SkelAnimation carries it
    # 1.5 m along x and 0.3 m up between frames 1 and 3, under a SkelRoot moved 0.2 m along z;
    # where the box should be is worked out here from the animation (the joint's translation
    # and the root's), not by UsdSkel: at frame 3 the box's colour shows there and not at its
    # rest place; the automatic camera frames the posed box, not the rest one
    from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

    from simbake.preview import Preview, _color

    path = write_stage(tmp_path / "skinned.usda")
    stage = Usd.Stage.Open(str(path))
    for prim in ("/World/box", "/World/sheet"):
        stage.RemovePrim(prim)
    root = UsdSkel.Root.Define(stage, "/World/Figure")
    root.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.2))
    skeleton = UsdSkel.Skeleton.Define(stage, "/World/Figure/Skel")
    skeleton.CreateJointsAttr(Vt.TokenArray(["root"]))
    rest = Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*BOX_CENTER))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([rest]))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray([rest]))
    anim = UsdSkel.Animation.Define(stage, "/World/Figure/Skel/Anim")
    anim.CreateJointsAttr(Vt.TokenArray(["root"]))
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0, 1.0, 1.0)]))
    moved = {f: BOX_CENTER + np.array([0.75, 0.15, 0.0]) * (f - 1) for f in (1, 2, 3)}
    for f, at in moved.items():
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*at)]), f)
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    h = BOX_SIZE / 2
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = UsdGeom.Mesh.Define(stage, "/World/Figure/Body")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*(np.array(c) + BOX_CENTER)) for c in corners]))
    mesh.CreateFaceVertexCountsAttr([4] * 6)
    mesh.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
    binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    stage.GetRootLayer().Save()

    base = np.array(_color("/World/Figure/Body"))

    def is_box(pixel):
        pixel = pixel.astype(float)
        return pixel @ base / (np.linalg.norm(pixel) * np.linalg.norm(base)) > 0.998 and not is_grey(pixel)

    offset = np.array([0.0, 0.0, 0.2])
    for frame in (1, 3):
        image = render(path, frames=str(frame))
        front = moved[frame] + offset + [0.0, 0.0, h]       # the front face's centre at this frame
        assert is_box(image[project(front)[::-1]]), (frame, image[project(front)[::-1]])
        if frame == 3:
            rest = moved[1] + offset + [0.0, 0.0, h]
            assert not is_box(image[project(rest)[::-1]]), image[project(rest)[::-1]]
    preview = Preview(path, (W, H))
    try:
        lo, hi, _, _ = preview.frame_range([3])
    finally:
        preview.close()
    np.testing.assert_allclose(lo[[0, 2]], (moved[3] + offset - h)[[0, 2]], atol=1e-5)  # (y: the ground's)
    np.testing.assert_allclose(hi, moved[3] + offset + h, atol=1e-5)


@pytest.mark.parametrize("kind", ["Cube", "Sphere", "Capsule", "Cylinder", "Cone", "Plane"])
@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_gprim_tessellation_fills_its_extent_facing_out(kind, axis):
    # the tessellation spans the extent USD computes for the prim, and every triangle is
    # wound counterclockwise seen from the side its normals face, which is outwards
    from pxr import Usd, UsdGeom

    from simbake.preview import tessellate

    stage = Usd.Stage.CreateInMemory()
    prim = stage.DefinePrim("/shape", kind)
    for name, value in (("size", 0.7), ("radius", 0.3), ("height", 1.1), ("width", 3.0), ("length", 0.5)):
        if prim.GetAttribute(name):
            prim.GetAttribute(name).Set(value)
    if prim.GetAttribute("axis"):
        prim.GetAttribute("axis").Set(axis)
    points, corners, normals = tessellate(prim)
    extent = np.array(UsdGeom.Boundable(prim).ComputeExtent(Usd.TimeCode.Default()))
    assert np.allclose(points.min(axis=0), extent[0], atol=1e-6), (points.min(axis=0), extent)
    assert np.allclose(points.max(axis=0), extent[1], atol=1e-6), (points.max(axis=0), extent)
    tri = points[corners].reshape(-1, 3, 3)
    area = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    facing = normals.reshape(-1, 3, 3).mean(axis=1)
    solid = np.linalg.norm(area, axis=1) > 1e-9
    assert (np.einsum("ij,ij->i", area[solid], facing[solid]) > 0).all()
    assert (np.einsum("ij,ij->i", tri.mean(axis=1)[solid], facing[solid]) >= -1e-9).all()


def test_a_wall_plane_is_a_quad_and_a_ground_plane_the_ground(tmp_path):
    # a 1.6 x 1.0 m Plane facing the camera (axis Z) is drawn where it is, as a finite quad;
    # a 10 m Plane facing up at the recorded ground's height is the checkered ground (not a
    # quad over it), and neither blows up the automatic camera's framing of the box beside them
    from pxr import Gf, UsdGeom

    from simbake.preview import Preview

    path = tmp_path / "planes.usda"
    stage = gprim_stage(path)
    wall = UsdGeom.Plane.Define(stage, "/World/wall")
    wall.CreateAxisAttr(UsdGeom.Tokens.z)
    wall.CreateWidthAttr(1.6)
    wall.CreateLengthAttr(1.0)
    wall.AddTranslateOp().Set(Gf.Vec3d(1.0, 0.6, 0))
    ground = UsdGeom.Plane.Define(stage, "/World/ground")
    ground.CreateAxisAttr(UsdGeom.Tokens.y)
    ground.CreateWidthAttr(10.0)
    ground.CreateLengthAttr(10.0)
    cube = UsdGeom.Cube.Define(stage, "/World/cube")
    cube.CreateSizeAttr(1.0)
    cube.AddTranslateOp().Set(Gf.Vec3d(-1.2, 0.5, 0))
    stage.GetRootLayer().Save()
    image = render(path)
    col, row = project([1.0, 0.6, 0])
    assert not is_grey(image[row, col]), image[row, col]
    for point in ([1.0, 1.25, 0], [2.0, 0.6, 0]):  # beyond its edges: sky, ground
        col, row = project(point)
        assert is_grey(image[row, col]) or is_sky(image[row, col]), (point, image[row, col])
    for point in ([0.0, 0.0, 2.0], [-1.2, 0.0, 1.5]):  # the checkered ground, grey
        col, row = project(point)
        assert is_grey(image[row, col]) and image[row, col].min() > 60, (point, image[row, col])
    preview = Preview(path, (W, H))
    try:
        assert preview.geometry.ground_plane.GetPath() == "/World/ground"
        assert [d.prim.GetName() for d in preview.geometry.drawables] == ["wall", "cube"]
        lo, hi, _, _ = preview.frame_range([1])
        assert np.allclose(lo, [-1.7, 0, -0.5]) and np.allclose(hi, [-0.7, 1, 0.5]), (lo, hi)
    finally:
        preview.close()


# --------------------------------------------------------------------------------------------
# issue 30: exact sizes, bounded frames, reports tied to their caches
# --------------------------------------------------------------------------------------------

def test_a_single_frame_sheet_is_exactly_the_size_asked(tmp_path):
    """Issue 30, 20: `simbake preview CACHE -o f.png --frames 6:6 --size 320x180` wrote a
    328 x 188 image (a contact sheet's margin around one frame)."""
    from PIL import Image

    write_stage(tmp_path / "stage.usda", frames=8)
    result = run("preview", "stage.usda", "-o", "f.png", "--frames", "6:6", "--size", "320x180", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert Image.open(tmp_path / "f.png").size == (320, 180)


def test_previewing_ten_million_frames_is_refused_at_once(tmp_path):
    """Issue 30, 10: `simbake preview` of a 1e7-frame stage never ended (every frame listed,
    bounded and drawn). A movie of more than 10,000 frames is refused naming --frames; a
    contact sheet picks its 8 frames without listing the rest."""
    import time

    from simbake.preview import parse_frames

    stage = write_stage(tmp_path / "stage.usda")
    text = stage.read_text()
    stage.write_text(text.replace("endTimeCode = 3", "endTimeCode = 10000000"))
    assert "endTimeCode = 10000000" in stage.read_text()
    start = time.monotonic()
    result = run("preview", "stage.usda", "-o", "movie.mp4", cwd=tmp_path)
    assert result.returncode == 2 and "--frames" in result.stderr and "10,000,000 frames" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert time.monotonic() - start < 30
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stage.usda"]
    assert parse_frames(None, 1, 10_000_000, 8)[-1] == 10_000_000


def test_preview_of_a_directory_says_so(tmp_path):
    """Issue 30, 14: `simbake preview` of a directory said "no such file"."""
    (tmp_path / "cache.usdc").mkdir()
    for command in ("preview", "report"):
        result = run(command, "cache.usdc", "-o", f"out.{'png' if command == 'preview' else 'html'}", cwd=tmp_path)
        assert result.returncode == 2 and "is a directory" in result.stderr, result.stderr


def test_report_of_a_cache_the_sidecar_was_not_written_for_is_refused(write_scene, tmp_path):
    """Issue 30, 15: `simbake report garbage.usdc` with any `garbage.qa.json` beside it said
    "clean": the sidecar holds its cache's SHA-256 now."""
    path = write_scene(BOXES_ONE_CM_DEEP)
    assert run("bake", str(path), "-o", "x.usdc", "-q", cwd=tmp_path).returncode == 0
    (tmp_path / "garbage.usdc").write_bytes(b"garbage")
    (tmp_path / "garbage.qa.json").write_bytes((tmp_path / "x.qa.json").read_bytes())
    result = run("report", "garbage.usdc", cwd=tmp_path)
    assert result.returncode == 2 and "garbage.qa.json: cache_sha256: is the QA data of another cache" in result.stderr
    assert "garbage.report.html" not in {p.name for p in tmp_path.iterdir()}


@pytest.mark.parametrize("edit, key", [
    (lambda qa: qa["summary"].__setitem__("body_penetration", [1, 2]), "summary.body_penetration"),
    (lambda qa: qa["scene"]["settings"].pop("bodies"), "scene.settings.bodies"),
    (lambda qa: qa["figures"]["substeps"].append(3), "figures.substeps"),
    (lambda qa: qa.__setitem__("frames", "1-3"), "frames"),
])
def test_report_of_a_sidecar_of_the_wrong_shape_names_the_key(write_scene, tmp_path, edit, key):
    """Issue 30, 11: `simbake report` with a sidecar of the wrong shape was an internal error
    (exit 1)."""
    import json

    path = write_scene(BOXES_ONE_CM_DEEP)
    assert run("bake", str(path), "-o", "x.usdc", "-q", cwd=tmp_path).returncode == 0
    qa = json.loads((tmp_path / "x.qa.json").read_text())
    edit(qa)
    (tmp_path / "x.qa.json").write_text(json.dumps(qa))
    result = run("report", "x.usdc", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"simbake: error: x.qa.json: {key}"), lines
