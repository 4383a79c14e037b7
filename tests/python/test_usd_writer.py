"""USD cache v1: the streaming writer (simbake.usd_writer) and the checker (simbake.check)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

from simbake.check import check_cache
from simbake.errors import SimulationError
from simbake.usd_writer import BodyPrim, CacheWriter, ClothPrim

FPS = 24.0
START, END = 3, 14  # not starting at 0 or 1 on purpose
NFRAMES = END - START + 1


# --------------------------------------------------------------------------------------------
# fixtures: a tetrahedron body mesh, a 3x3-vertex cloth grid, a deterministic motion
# --------------------------------------------------------------------------------------------

def tetra(name: str, dynamic: bool) -> BodyPrim:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float) - 0.25
    nrm = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    return BodyPrim(name=name, points=pts, face_vertex_counts=np.full(4, 3, np.int32),
                    face_vertex_indices=np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], np.int32),
                    normals=nrm, dynamic=dynamic)


def grid_cloth(name: str = "sheet", n: int = 3) -> ClothPrim:
    quads = [[j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i]
             for j in range(n - 1) for i in range(n - 1)]
    return ClothPrim(name=name, face_vertex_counts=np.full(len(quads), 4, np.int32),
                     face_vertex_indices=np.array(quads, np.int32).reshape(-1))


def quat(angle: float, axis=(0.0, 1.0, 0.0)) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * a])


def motion(frame: int, n: int = 3):
    """Poses of [static 'floor', dynamic 'crate'] and the cloth state at ``frame``."""
    k = frame - START
    translations = np.array([[0.0, -0.5, 0.0], [0.1 * k, 2.0 - 0.01 * k * k, 1.0 / 3.0]])
    orientations = np.array([[1.0, 0.0, 0.0, 0.0], quat(0.3 * k, (1.0, 2.0, 3.0))])
    x, z = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    y = 1.0 - 0.05 * k + 0.1 * np.sin(x * k)
    points = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    velocities = np.tile([0.0, -0.05 * FPS, 0.0], (n * n, 1))
    normals = np.tile([0.0, 1.0, 0.0], (n * n, 1))
    return translations, orientations, points, velocities, normals


def write_cache(path: Path, *, flush_every: int = 4, with_normals: bool = True,
                provenance=None) -> Path:
    bodies = [tetra("floor", dynamic=False), tetra("crate", dynamic=True)]
    with CacheWriter(path, fps=FPS, start_frame=START, end_frame=END, bodies=bodies,
                     cloths=[grid_cloth()], flush_every=flush_every,
                     provenance=provenance if provenance is not None else {
                         "simbake_version": "0.0.test", "scene_hash": "abc123",
                         "solver": {"substeps": 0, "gravity": (0.0, -9.81, 0.0)}}) as w:
        for f in range(START, END + 1):
            t, q, p, v, n = motion(f)
            w.write_frame(f, t, q, [p], [v], [n] if with_normals else [])
    return path


@pytest.fixture
def cache(tmp_path) -> Path:
    return write_cache(tmp_path / "cache.usdc")


def open_stage(path: Path) -> Usd.Stage:
    return Usd.Stage.Open(str(path))


def leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if ".tmp" in p.name)


# --------------------------------------------------------------------------------------------
# the written cache
# --------------------------------------------------------------------------------------------

def test_stage_metadata(cache):
    stage = open_stage(cache)
    layer = stage.GetRootLayer()
    assert layer.defaultPrim == "World"
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert stage.HasAuthoredMetadata("metersPerUnit")
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdPhysics.StageHasAuthoredKilogramsPerUnit(stage)
    assert UsdPhysics.GetStageKilogramsPerUnit(stage) == 1.0
    assert layer.HasTimeCodesPerSecond() and layer.HasFramesPerSecond()
    assert layer.timeCodesPerSecond == FPS and layer.framesPerSecond == FPS
    assert (layer.startTimeCode, layer.endTimeCode) == (START, END)
    data = layer.customLayerData
    assert data["simbake_version"] == "0.0.test"
    assert data["scene_hash"] == "abc123"
    assert data["solver"]["substeps"] == 0
    assert list(data["solver"]["gravity"]) == [0.0, -9.81, 0.0]
    world = stage.GetPrimAtPath("/World")
    assert world.GetTypeName() == "Xform"
    assert Usd.ModelAPI(world).GetKind() == "component"


def test_prim_layout(cache):
    stage = open_stage(cache)
    for name in ("floor", "crate"):
        xf = stage.GetPrimAtPath(f"/World/{name}")
        assert xf.GetTypeName() == "Xform"
        ops = UsdGeom.Xformable(xf).GetOrderedXformOps()
        assert [op.GetOpName() for op in ops] == ["xformOp:translate", "xformOp:orient"]
        assert xf.GetAttribute("xformOp:translate").GetTypeName() == Sdf.ValueTypeNames.Double3
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/{name}/{name}"))
        assert mesh and mesh.GetPrim().GetTypeName() == "Mesh"
        assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
        assert mesh.GetOrientationAttr().Get() == "rightHanded"
        assert mesh.GetNormalsInterpolation() == "vertex"
        np.testing.assert_allclose(np.array(mesh.GetPointsAttr().Get()),
                                   tetra(name, False).points)
        assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3, 3, 3, 3]
        for attr in mesh.GetPrim().GetAttributes():
            assert attr.GetNumTimeSamples() == 0, attr.GetPath()
        assert len(mesh.GetExtentAttr().Get()) == 2
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    assert cloth.GetPrim().GetTypeName() == "Mesh"
    assert cloth.GetSubdivisionSchemeAttr().Get() == "none"
    assert cloth.GetNormalsInterpolation() == "vertex"


def test_sample_counts(cache):
    stage = open_stage(cache)
    frames = [float(f) for f in range(START, END + 1)]
    crate = stage.GetPrimAtPath("/World/crate")
    for name in ("xformOp:translate", "xformOp:orient"):
        assert crate.GetAttribute(name).GetTimeSamples() == frames
    sheet = stage.GetPrimAtPath("/World/sheet")
    for name in ("points", "normals", "velocities", "extent"):
        assert sheet.GetAttribute(name).GetTimeSamples() == frames, name
    # nothing else anywhere is sampled
    sampled = {str(a.GetPath()) for p in stage.Traverse() for a in p.GetAttributes()
               if a.GetNumTimeSamples()}
    assert sampled == {"/World/crate.xformOp:translate", "/World/crate.xformOp:orient",
                       "/World/sheet.points", "/World/sheet.normals",
                       "/World/sheet.velocities", "/World/sheet.extent"}


def test_values_read_back(cache):
    stage = open_stage(cache)
    crate = UsdGeom.Xformable(stage.GetPrimAtPath("/World/crate"))
    translate = crate.GetPrim().GetAttribute("xformOp:translate")
    orient = crate.GetPrim().GetAttribute("xformOp:orient")
    assert orient.GetTypeName() == Sdf.ValueTypeNames.Quatd
    sheet = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    for f in (START, START + 1, (START + END) // 2, END):
        t, q, p, v, n = motion(f)
        got_t = translate.Get(f)
        assert isinstance(got_t, Gf.Vec3d)
        assert tuple(got_t) == tuple(t[1])  # double precision: exact
        got_q = orient.Get(f)
        assert (got_q.GetReal(), *got_q.GetImaginary()) == tuple(q[1])
        # the composed transform places the mesh origin at the translation
        m = crate.ComputeLocalToWorldTransform(f)
        np.testing.assert_allclose(np.array(m.ExtractTranslation()), t[1], atol=1e-12)
        rot = Gf.Rotation(Gf.Quatd(*q[1]))
        np.testing.assert_allclose(np.array(m.TransformDir(Gf.Vec3d(1, 0, 0))),
                                   np.array(rot.TransformDir(Gf.Vec3d(1, 0, 0))), atol=1e-12)
        np.testing.assert_array_equal(np.array(sheet.GetPointsAttr().Get(f)),
                                      p.astype(np.float32))
        np.testing.assert_array_equal(np.array(sheet.GetVelocitiesAttr().Get(f)),
                                      v.astype(np.float32))
        np.testing.assert_array_equal(np.array(sheet.GetNormalsAttr().Get(f)),
                                      n.astype(np.float32))
        ext = np.array(sheet.GetExtentAttr().Get(f))
        np.testing.assert_array_equal(ext, [p.astype(np.float32).min(0),
                                            p.astype(np.float32).max(0)])


def test_static_body_has_no_time_samples(cache):
    stage = open_stage(cache)
    floor = stage.GetPrimAtPath("/World/floor")
    t, q, *_ = motion(START)
    for name in ("xformOp:translate", "xformOp:orient"):
        attr = floor.GetAttribute(name)
        assert attr.GetNumTimeSamples() == 0
        assert attr.HasAuthoredValue()
    assert tuple(floor.GetAttribute("xformOp:translate").Get()) == tuple(t[0])
    got = floor.GetAttribute("xformOp:orient").Get()
    assert (got.GetReal(), *got.GetImaginary()) == tuple(q[0])


def test_cloth_topology_written_once(cache):
    stage = open_stage(cache)
    sheet = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    for attr in (sheet.GetFaceVertexCountsAttr(), sheet.GetFaceVertexIndicesAttr(),
                 sheet.GetSubdivisionSchemeAttr(), sheet.GetOrientationAttr()):
        assert attr.HasAuthoredValue() and attr.GetNumTimeSamples() == 0, attr.GetPath()
    cloth = grid_cloth()
    assert list(sheet.GetFaceVertexCountsAttr().Get()) == cloth.face_vertex_counts.tolist()
    assert list(sheet.GetFaceVertexIndicesAttr().Get()) == cloth.face_vertex_indices.tolist()


def test_cloth_normals_computed_when_omitted(tmp_path):
    path = write_cache(tmp_path / "n.usdc", with_normals=False)
    stage = open_stage(path)
    sheet = UsdGeom.Mesh(stage.GetPrimAtPath("/World/sheet"))
    assert sheet.GetNormalsAttr().GetNumTimeSamples() == NFRAMES
    n = np.array(sheet.GetNormalsAttr().Get(START))  # flat grid at the first frame
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)
    # faces (i, i+1, i+n+1, i+n) wind from +x towards +z: right-handed normal is -y
    np.testing.assert_allclose(n, np.tile([0.0, -1.0, 0.0], (9, 1)), atol=1e-6)
    assert check_cache(path) == []


# --------------------------------------------------------------------------------------------
# formats, files, atomicity, determinism
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("suffix,magic", [(".usdc", b"PXR-USDC"), (".usd", b"PXR-USDC"),
                                          (".usda", b"#usda 1.0")])
def test_format_from_suffix(tmp_path, suffix, magic):
    path = write_cache(tmp_path / f"cache{suffix}")
    assert path.read_bytes().startswith(magic)
    stage = open_stage(path)
    assert stage.GetPrimAtPath("/World/crate").GetAttribute(
        "xformOp:translate").GetNumTimeSamples() == NFRAMES
    assert check_cache(path) == []
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("name", ["cache.abc", "cache.usdz", "cache", "cache.txt"])
def test_unknown_suffix_rejected(tmp_path, name):
    with pytest.raises(ValueError, match="extension"):
        CacheWriter(tmp_path / name, fps=24, start_frame=1, end_frame=2, bodies=[])
    assert list(tmp_path.iterdir()) == []


def test_file_appears_only_on_close(tmp_path):
    path = tmp_path / "late.usdc"
    w = CacheWriter(path, fps=FPS, start_frame=START, end_frame=END,
                    bodies=[tetra("crate", True)], flush_every=2)
    for f in range(START, END + 1):
        t, q, *_ = motion(f)
        w.write_frame(f, t[1:], q[1:])
        assert not path.exists()
    assert len(leftovers(tmp_path)) == 1  # streamed to a temp file beside the target
    assert w.close() == path
    assert path.exists() and leftovers(tmp_path) == []
    assert check_cache(path) == []


def test_abort_removes_temp_file_and_keeps_existing_target(tmp_path):
    path = tmp_path / "cache.usdc"
    path.write_bytes(b"precious old cache")
    w = CacheWriter(path, fps=FPS, start_frame=START, end_frame=END,
                    bodies=[tetra("crate", True)], flush_every=1)
    for f in range(START, START + 5):
        t, q, *_ = motion(f)
        w.write_frame(f, t[1:], q[1:])
    assert leftovers(tmp_path)
    w.abort()
    assert leftovers(tmp_path) == []
    assert path.read_bytes() == b"precious old cache"
    w.abort()  # idempotent
    with pytest.raises(RuntimeError):
        w.close()
    assert path.read_bytes() == b"precious old cache"


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_exception_in_with_block_aborts(tmp_path, suffix):
    path = tmp_path / f"cache{suffix}"
    path.write_text("old")
    with pytest.raises(KeyError):
        with CacheWriter(path, fps=FPS, start_frame=START, end_frame=END,
                         bodies=[tetra("crate", True)]) as w:
            t, q, *_ = motion(START)
            w.write_frame(START, t[1:], q[1:])
            raise KeyError("solver blew up")
    assert leftovers(tmp_path) == []
    assert path.read_text() == "old"


def test_close_with_missing_frames_raises_and_cleans_up(tmp_path):
    path = tmp_path / "short.usdc"
    w = CacheWriter(path, fps=FPS, start_frame=START, end_frame=END,
                    bodies=[tetra("crate", True)])
    t, q, *_ = motion(START)
    w.write_frame(START, t[1:], q[1:])
    with pytest.raises(RuntimeError, match="not written"):
        w.close()
    assert not path.exists() and leftovers(tmp_path) == []


def test_unreferenced_writer_leaves_no_temp_file(tmp_path):
    w = CacheWriter(tmp_path / "gc.usdc", fps=FPS, start_frame=1, end_frame=3,
                    bodies=[tetra("crate", True)])
    assert leftovers(tmp_path)
    del w
    import gc
    gc.collect()
    assert leftovers(tmp_path) == []


def test_frames_in_order_exactly_once(tmp_path):
    w = CacheWriter(tmp_path / "order.usdc", fps=FPS, start_frame=START, end_frame=END,
                    bodies=[tetra("crate", True)])
    t, q, *_ = motion(START)
    with pytest.raises(ValueError, match="expected frame"):
        w.write_frame(START + 1, t[1:], q[1:])
    w.write_frame(START, t[1:], q[1:])
    with pytest.raises(ValueError, match="expected frame"):
        w.write_frame(START, t[1:], q[1:])
    with pytest.raises(ValueError, match="shape|expected translations"):
        w.write_frame(START + 1, t, q)  # two bodies' worth for one body
    with pytest.raises(SimulationError):
        w.write_frame(START + 1, [[np.nan, 0, 0]], q[1:])
    w.abort()
    assert leftovers(tmp_path) == []


def test_bad_prims_rejected(tmp_path):
    with pytest.raises(ValueError, match="prim name"):
        tetra("not a name", True)
    with pytest.raises(ValueError, match="sum"):
        ClothPrim("c", [3, 3], [0, 1, 2])
    with pytest.raises(ValueError, match="duplicate"):
        CacheWriter(tmp_path / "d.usdc", fps=24, start_frame=1, end_frame=2,
                    bodies=[tetra("a", True)], cloths=[ClothPrim("a", [3], [0, 1, 2])])
    assert list(tmp_path.iterdir()) == []


def test_static_body_that_moves_is_an_error(tmp_path):
    w = CacheWriter(tmp_path / "s.usdc", fps=FPS, start_frame=1, end_frame=3,
                    bodies=[tetra("floor", False)])
    w.write_frame(1, [[0, 0, 0]], [[1, 0, 0, 0]])
    w.write_frame(2, [[0, 0, 0]], [[1, 0, 0, 0]])
    with pytest.raises(ValueError, match="static body 'floor' moved"):
        w.write_frame(3, [[0, 1, 0]], [[1, 0, 0, 0]])
    w.abort()


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_byte_identical_output(tmp_path, suffix):
    a = write_cache(tmp_path / f"a{suffix}")
    b = write_cache(tmp_path / f"b{suffix}")
    assert a.read_bytes() == b.read_bytes()


def test_flush_interval_does_not_change_content(tmp_path):
    a = write_cache(tmp_path / "a.usda", flush_every=1)
    b = write_cache(tmp_path / "b.usda", flush_every=1000)
    assert a.read_bytes() == b.read_bytes()
    c = write_cache(tmp_path / "c.usdc", flush_every=1)
    assert check_cache(c) == []
    sa, sc = open_stage(a), open_stage(c)
    for path in ("/World/crate.xformOp:translate", "/World/sheet.points"):
        for f in range(START, END + 1):
            assert sa.GetAttributeAtPath(path).Get(f) == sc.GetAttributeAtPath(path).Get(f)


def test_provenance_types(tmp_path):
    prov = {"version": "1.2", "hash": "f00", "count": np.int64(3), "dt": np.float32(0.5),
            "flag": True, "path": Path("scene.toml"), "ints": [1, 2, 3],
            "floats": np.array([0.5, 1.0]), "names": ("a", "b"), "mixed": [1, "x"],
            "nested": {"deep": {"x": 1.5}}, "skipped": None}
    path = write_cache(tmp_path / "p.usda", provenance=prov)
    stage = open_stage(path)
    data = stage.GetRootLayer().customLayerData
    assert data["version"] == "1.2" and data["count"] == 3 and data["dt"] == 0.5
    assert data["flag"] is True and data["path"] == "scene.toml"
    assert list(data["ints"]) == [1, 2, 3] and list(data["floats"]) == [0.5, 1.0]
    assert list(data["names"]) == ["a", "b"]
    assert data["mixed"] == {"0000": 1, "0001": "x"}
    assert data["nested"]["deep"]["x"] == 1.5
    assert "skipped" not in data
    assert check_cache(path) == []


# --------------------------------------------------------------------------------------------
# the checker
# --------------------------------------------------------------------------------------------

def test_check_good_cache(cache):
    assert check_cache(cache) == []
    assert check_cache(str(cache)) == []


def test_check_missing_file(tmp_path):
    problems = check_cache(tmp_path / "nope.usdc")
    assert len(problems) == 1 and "nope.usdc" in problems[0]


def test_check_not_usd(tmp_path):
    bad = tmp_path / "junk.usdc"
    bad.write_bytes(b"not a crate file")
    problems = check_cache(bad)
    assert len(problems) == 1 and "junk.usdc" in problems[0] and "\n" not in problems[0]


def edit(path: Path, fn) -> None:
    layer = Sdf.Layer.FindOrOpen(str(path))
    fn(layer)
    assert layer.Save()
    del layer


def test_check_finds_nan(cache):
    nan_frame = START + 4

    def inject(layer):
        layer.SetTimeSample("/World/crate.xformOp:translate", nan_frame,
                            Gf.Vec3d(0.0, float("nan"), 0.0))
    edit(cache, inject)
    problems = check_cache(cache)
    assert any("/World/crate.xformOp:translate" in p and "NaN" in p
               and f"frame {nan_frame}" in p for p in problems), problems


def test_check_finds_nan_in_points_and_default(tmp_path):
    path = write_cache(tmp_path / "c.usda")

    def inject(layer):
        pts = np.array(layer.QueryTimeSample("/World/sheet.points", END))
        pts[4, 2] = np.inf
        from pxr import Vt
        layer.SetTimeSample("/World/sheet.points", END, Vt.Vec3fArray.FromNumpy(pts))
        layer.GetAttributeAtPath("/World/floor.xformOp:translate").default = \
            Gf.Vec3d(float("nan"), 0, 0)
    edit(path, inject)
    problems = check_cache(path)
    assert any("/World/sheet.points" in p and f"frame {END}" in p for p in problems), problems
    assert any("/World/floor.xformOp:translate" in p and "default" in p
               for p in problems), problems


def test_check_finds_missing_frame(cache):
    edit(cache, lambda layer: layer.EraseTimeSample("/World/sheet.velocities", START + 2))
    problems = check_cache(cache)
    assert len(problems) == 1, problems
    assert "/World/sheet.velocities" in problems[0] and f"first {START + 2}" in problems[0]


def test_check_finds_extra_and_fractional_samples(cache):
    def inject(layer):
        v = layer.QueryTimeSample("/World/crate.xformOp:translate", START)
        layer.SetTimeSample("/World/crate.xformOp:translate", START + 0.5, v)
        layer.SetTimeSample("/World/crate.xformOp:translate", END + 1, v)
    edit(cache, inject)
    problems = check_cache(cache)
    assert len(problems) == 1 and "2 time sample(s) outside" in problems[0], problems


def test_check_finds_non_unit_quaternion(cache):
    edit(cache, lambda layer: layer.SetTimeSample("/World/crate.xformOp:orient", END,
                                                  Gf.Quatd(1.0, 0.0, 1e-2, 0.0)))
    problems = check_cache(cache)
    assert len(problems) == 1 and "quaternion" in problems[0] and f"frame {END}" in problems[0]


def test_check_finds_bad_extent(cache):
    from pxr import Vt
    edit(cache, lambda layer: layer.SetTimeSample(
        "/World/sheet.extent", START + 1,
        Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(0.1, 0.1, 0.1)])))
    problems = check_cache(cache)
    assert len(problems) == 1 and "extent" in problems[0] and f"frame {START + 1}" in problems[0]


def test_check_finds_metadata_problems(cache):
    def inject(layer):
        layer.framesPerSecond = 30.0
        layer.ClearEndTimeCode()
        layer.pseudoRoot.SetInfo("upAxis", "Z")
    edit(cache, inject)
    problems = check_cache(cache)
    text = "\n".join(problems)
    assert "framesPerSecond" in text and "endTimeCode" in text and "upAxis" in text, problems


def test_check_reports_validator_errors(cache):
    # metersPerUnit missing is an error of usdGeomValidators:StageMetadataChecker
    edit(cache, lambda layer: layer.pseudoRoot.ClearInfo("metersPerUnit"))
    problems = check_cache(cache)
    assert any("usd error" in p and "MissingMetersPerUnitMetadata" in p for p in problems)
    assert any("metersPerUnit must be 1" in p for p in problems)
    assert all("\n" not in p for p in problems)


def test_check_sees_file_rewritten_while_layer_is_held(tmp_path):
    path = write_cache(tmp_path / "held.usdc")
    held = Sdf.Layer.FindOrOpen(str(path))  # someone in the process keeps the layer open
    assert check_cache(path) == []
    other = write_cache(tmp_path / "other.usdc")
    edit(other, lambda layer: layer.EraseTimeSample("/World/sheet.points", END))
    os.replace(other, path)
    problems = check_cache(path)
    assert len(problems) == 1 and "/World/sheet.points" in problems[0], problems
    del held
