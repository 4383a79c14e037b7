"""`simbake preview`: a headless CPU render of a USD cache, as a contact sheet or a movie.

What is drawn: every `Mesh` of the stage (a body's mesh under its Xform, a cloth), every
UsdGeom gprim a USD shot's bodies are (`Cube`, `Sphere`, `Capsule`, `Cylinder`, `Cone`,
tessellated once per prim: hard edges for the cube, smooth elsewhere; a `Plane` as a finite
quad) and every `PointInstancer`'s prototype meshes and gprims at each instance, with their
full composed transforms at each time and a mesh's authored normals (so a preview shades as
a renderer would: smooth where the cache says smooth). A mesh that UsdSkel skins (a shot's
character, in a `--shot` stage) is drawn at each frame's pose: OpenUSD's own skinning
(`UsdSkelSkinningQuery.ComputeSkinnedPoints`, then the skeleton's world transform, as
simbake.usd_deforming reads it for the solver), shaded by normals of the skinned surface
(simbake.normals, its creases kept). All under a key light and a fill from the
camera, on a checkered ground plane. Double-sided meshes and SimbakeClothAPI meshes (the
cloth) show their front in orange and their back in blue, so a layer passing through
another, or a cloth seen from behind, shows at once. Guides (level sets) are not drawn.

Camera: `auto` frames the whole animation's extent (the union of the world bounds of every
rendered frame, Planes left out when anything else is drawn) from the front, right and
above; or the path of a `Camera` prim of the stage. The ground is the scene's ground
(recorded in a TOML scene's cache's customLayerData), or a shot's ground: the lowest still
Plane facing up, drawn as the checkered ground at its height instead of as a quad; or a
reference plane just under the animation's extent when there is none.

Renderer: OpenGL 3.3 through moderngl on an EGL context on Mesa's llvmpipe (a CPU
rasterizer: no GPU, no display), 4x multisampled, with a shadow map from the key light so
that contact with the ground reads. Chosen by measurement against VTK
(OSMesa) and Mitsuba 3 (see benchmarks/results/preview_renderers.md): the fastest by far at
1280x720, the smallest install, and exact depth and two-sided colours. The frame number and
time are burned in with Pillow; movies are written with imageio (ffmpeg for MP4, Pillow for
GIF) at the cache's frame rate.

Outputs: `.png` a contact sheet (a grid of frames, default 8 evenly spaced ones, 480x270
each); `.mp4` or `.gif` a movie (default every frame, 960x540). Written beside and renamed,
so a failed preview leaves no partial file.
"""

from __future__ import annotations

import colorsys
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from .errors import SceneError
from .files import check_input_file, check_output_path, write_atomically
from .normals import corner_normals

OUTPUT_SUFFIXES = (".png", ".mp4", ".gif")
SHEET_FRAMES = 8                 # frames on a contact sheet when --frames is not given
SHEET_SIZE = (480, 270)          # a contact sheet's tiles (pixels)
MOVIE_SIZE = (960, 540)          # a movie's frames (pixels)
MAX_PIXELS = 4096 * 4096         # largest frame (llvmpipe's framebuffer limit is 8192 a side)
MAX_FRAMES = 10_000              # frames one preview draws (7 minutes at 24 fps; ~20 minutes
                                 # of rendering at 960x540)
MSAA_SAMPLES = 4
FOV_Y = math.radians(35.0)       # the automatic camera's vertical field of view
VIEW_DIRECTION = np.array([0.55, 0.62, 1.0])  # automatic camera: from front right, 28 degrees
                                              # above (turned to look across the longer side)
LIGHT_DIRECTION = np.array([-0.35, 0.85, 0.4])  # towards the key light (display space, Y up)
CLOTH_FRONT = (0.93, 0.52, 0.16)  # orange
CLOTH_BACK = (0.20, 0.42, 0.88)   # blue
SKY = (0.86, 0.90, 0.95)
GROUND_COLORS = ((0.66, 0.66, 0.64), (0.72, 0.72, 0.70))
SHADOW_MAPS = (1024, 2048)       # pixels a side: for frames up to 960 wide (a quarter of the
                                 # time at 640x360), and larger
INSTALL_HINT = ("install the preview extra: pip install 'simbake[preview]' (make demo does), "
                "and Debian's libegl1 libgl1-mesa-dri")


# --------------------------------------------------------------------------------------------
# options


def parse_size(text: str, key: str = "--size") -> tuple[int, int]:
    """'WxH' -> (W, H); each a positive even number (video encoders need even sizes)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SceneError(text, key, "must be WIDTHxHEIGHT in pixels, e.g. 1280x720") from None
    if w < 16 or h < 16 or w * h > MAX_PIXELS:
        raise SceneError(text, key, f"must be at least 16x16 and at most {MAX_PIXELS} pixels, got {w}x{h}")
    return w - w % 2, h - h % 2


def parse_frames(text: str | None, start: int, end: int, default_count: int | None) -> list[int]:
    """'A:B[:STEP]' (inclusive, either end may be left out) or 'A' -> frame numbers within
    [start, end]; None -> every frame, or `default_count` evenly spaced ones. At most
    MAX_FRAMES frames (a render of a 1e7-frame stage would never end): more is an error
    naming --frames."""
    if text is None:
        count = end - start + 1
        if default_count is not None and count > default_count:
            picks = np.linspace(0, count - 1, default_count).round().astype(np.int64)
            return [start + int(k) for k in sorted(set(picks.tolist()))]
        return _within_budget(range(start, end + 1), f"{start}:{end}")
    parts = text.split(":")
    try:
        if len(parts) == 1:
            a = b = int(parts[0])
            step = 1
        elif len(parts) in (2, 3):
            a = int(parts[0]) if parts[0] else start
            b = int(parts[1]) if parts[1] else end
            step = int(parts[2]) if len(parts) == 3 and parts[2] else 1
        else:
            raise ValueError
    except ValueError:
        raise SceneError(text, "--frames", "must be A:B[:STEP] or A, whole frame numbers") from None
    if step < 1:
        raise SceneError(text, "--frames", f"STEP must be >= 1, got {step}")
    if a > b or a < start or b > end:
        raise SceneError(text, "--frames", f"must lie within the cache's frames {start}:{end}, in order")
    return _within_budget(range(a, b + 1, step), text)


def _within_budget(frames: range, text: str) -> list[int]:
    if len(frames) > MAX_FRAMES:
        raise SceneError(text, "--frames", f"{len(frames):,} frames is more than a preview draws (at most "
                                           f"{MAX_FRAMES:,}); give a shorter range or a STEP (A:B:STEP)")
    return list(frames)


# --------------------------------------------------------------------------------------------
# what the cache holds, in display space (Y up)


@dataclass
class _Drawable:
    """A mesh to draw: its triangulation (fan per polygon) and colours; `instancer` set when
    it is a prototype drawn at every instance of a PointInstancer."""

    prim: object                 # Usd.Prim of the mesh
    corners: np.ndarray          # (3t,) int: the point index of each triangle corner
    face_of_corner: np.ndarray   # (3t,) int: the polygon of each triangle corner
    face_vertex: np.ndarray      # (3t,) int: the face-vertex slot of each triangle corner
    front: tuple[float, float, float]
    back: tuple[float, float, float]
    instancer: object = None     # UsdGeom.PointInstancer drawing this prototype
    prototype: object = None     # the prototype root prim the mesh sits under
    proto_index: int = -1
    points: np.ndarray | None = None   # a gprim's tessellation (prim space), fixed: (p, 3)
    normals: np.ndarray | None = None  # and its normal at each triangle corner: (3t, 3)
    skinning: tuple | None = None      # (UsdSkelSkinningQuery, UsdSkelSkeletonQuery) of a skinned mesh


def _color(name: str) -> tuple[float, float, float]:
    """A muted colour from a prim's name, the same on every run."""
    hue = int(hashlib.sha256(name.encode()).hexdigest()[:8], 16) / 0xFFFFFFFF
    return colorsys.hls_to_rgb(hue, 0.58, 0.38)


def _triangulate(counts: np.ndarray, indices: np.ndarray, left_handed: bool):
    """Fan triangulation: (point index, polygon, face-vertex slot) of every triangle corner."""
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    starts = np.zeros(len(counts), dtype=np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    slots, faces = [], []
    for c in np.unique(counts):
        if c < 3:
            continue
        polygons = np.nonzero(counts == c)[0]
        for k in range(1, c - 1):
            order = (0, k + 1, k) if left_handed else (0, k, k + 1)
            tri = np.stack([starts[polygons] + o for o in order], axis=1)
            slots.append(tri.reshape(-1))
            faces.append(np.repeat(polygons, 3))
    if not slots:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    slot = np.concatenate(slots)
    face = np.concatenate(faces)
    return indices[slot], face, slot

# gprims (Cube, Sphere, Capsule, Cylinder, Cone, Plane) are tessellated once, in prim space;
# round ones as a profile (rows of radius, height along the axis, normal) turned about it
SEGMENTS = 48                    # around the axis of a round gprim
RINGS = 24                       # from pole to pole of a sphere (half each for a capsule's caps)
_AXES = {"X": (1, 2, 0), "Y": (2, 0, 1), "Z": (0, 1, 2)}  # (u, v, axis): u x v = axis


def _revolve(parts: Sequence[Sequence[tuple[float, float, float, float]]], axis: str):
    """Points, triangle corners and corner normals of the surface swept by turning each part
    of a profile (rows (radius, height, radial normal, axial normal), from the -axis end to the
    +axis end) about `axis`; normals are smooth within a part and break between parts."""
    u, v, a = _AXES.get(str(axis), _AXES["Z"])
    theta = np.linspace(0.0, 2 * math.pi, SEGMENTS + 1)[:-1]
    ring = np.zeros((SEGMENTS, 3))
    ring[:, u], ring[:, v] = np.cos(theta), np.sin(theta)
    up = np.zeros(3)
    up[a] = 1.0
    points, normals, corners = [], [], []
    count = 0
    for part in parts:
        rows = np.asarray(part, dtype=np.float64)
        for r, h, nr, na in rows:
            points.append(r * ring + h * up)
            normals.append(nr * ring + na * up)
        j = np.arange(SEGMENTS)
        k = (j + 1) % SEGMENTS
        for row in range(len(rows) - 1):
            lo, hi = count + row * SEGMENTS, count + (row + 1) * SEGMENTS
            corners.append(np.stack([lo + j, lo + k, hi + k, lo + j, hi + k, hi + j], axis=1).reshape(-1))
        count += len(rows) * SEGMENTS
    points, normals = np.concatenate(points), np.concatenate(normals)
    corners = np.concatenate(corners)
    return points, corners, normals[corners]


def _cap(radius: float, height: float, sign: float):
    """A flat disc closing a cylinder or cone at `height`, facing `sign` along the axis."""
    rows = [(0.0, height, 0.0, sign), (radius, height, 0.0, sign)]
    return rows if sign < 0 else rows[::-1]


def _box(half: np.ndarray):
    """A box of half sizes `half`: 6 quads, hard edges (corner normals are the faces')."""
    points, normals = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, v = (axis + 1) % 3, (axis + 2) % 3
            if sign < 0:
                u, v = v, u  # counterclockwise seen from outside
            quad = []
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = n.copy()
                p[u], p[v] = a, b
                quad.append(p * half)
            points.extend(quad)
            normals.extend([n] * 4)
    base = np.arange(6)[:, None] * 4
    corners = (base + np.array([0, 1, 2, 0, 2, 3])).reshape(-1)
    return np.array(points), corners, np.array(normals)[corners]


def _plane(width: float, length: float, axis: str):
    """A Plane's finite quad: width along x (z when the axis is X), length along y (z when Y)."""
    u, v, a = {"X": (2, 1, 0), "Y": (0, 2, 1), "Z": (0, 1, 2)}.get(str(axis), (0, 1, 2))
    points = np.zeros((4, 3))
    for k, (s, t) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        points[k, u], points[k, v] = s * width / 2, t * length / 2
    n = np.zeros(3)
    n[a] = 1.0
    corners = np.array([0, 1, 2, 0, 2, 3])
    if np.dot(np.cross(points[1] - points[0], points[2] - points[0]), n) < 0:
        corners = corners[[0, 2, 1, 3, 5, 4]]
    return points, corners, np.repeat(n[None], 6, axis=0)


GPRIMS = ("Cube", "Sphere", "Capsule", "Cylinder", "Cone", "Plane")


def tessellate(prim):
    """(points, corners, corner normals) of a Cube, Sphere, Capsule, Cylinder, Cone or Plane,
    from its attributes at the earliest time; None for other prims or a degenerate size."""
    from pxr import Usd

    kind = prim.GetTypeName()
    if kind not in GPRIMS:
        return None

    def get(name, fallback):
        attr = prim.GetAttribute(name)
        value = attr.Get(Usd.TimeCode.EarliestTime()) if attr else None
        return fallback if value is None else value

    if kind == "Cube":
        size = float(get("size", 2.0))
        return _box(np.full(3, size / 2)) if size > 0 else None
    axis = get("axis", "Z")
    if kind == "Plane":
        width, length = (float(get(n, 2.0)) for n in ("width", "length"))
        width, length = (min(x, 1e4) for x in (width, length))  # an "infinite" plane: 10 km
        return _plane(width, length, axis) if width > 0 and length > 0 else None
    r = float(get("radius", 1.0))
    if not r > 0:
        return None
    phi = np.linspace(0.0, math.pi, RINGS + 1)
    if kind == "Sphere":
        return _revolve([[(r * math.sin(p), -r * math.cos(p), math.sin(p), -math.cos(p)) for p in phi]], "Z")
    h = float(get("height", 2.0 if kind != "Capsule" else 1.0))
    if kind == "Capsule":  # height: the spine between the centres of the two half spheres
        half = RINGS // 2
        rows = [(r * math.sin(p), (-h / 2 if k <= half else h / 2) - r * math.cos(p), math.sin(p), -math.cos(p))
                for k, p in enumerate(np.concatenate([phi[:half + 1], phi[half:]]))]
        return _revolve([rows], axis)
    if not h > 0:
        return None
    if kind == "Cylinder":
        side = [(r, -h / 2, 1.0, 0.0), (r, h / 2, 1.0, 0.0)]
        return _revolve([_cap(r, -h / 2, -1.0), side, _cap(r, h / 2, 1.0)], axis)
    slant = math.hypot(h, r)  # Cone: the base at -height/2, the apex at +height/2
    side = [(r, -h / 2, h / slant, r / slant), (0.0, h / 2, h / slant, r / slant)]
    return _revolve([_cap(r, -h / 2, -1.0), side], axis)


def _ancestors(prim):
    while prim and not prim.IsPseudoRoot():
        yield prim
        prim = prim.GetParent()


class CacheGeometry:
    """The drawable meshes of a USD stage and their world-space triangles at any time."""

    def __init__(self, stage):
        from pxr import Usd, UsdGeom

        self.stage = stage
        up = UsdGeom.GetStageUpAxis(stage)
        # display space is Y up: a Z-up stage is turned -90 degrees about x
        self.to_display = np.eye(4)
        if up == UsdGeom.Tokens.z:
            self.to_display[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
        self.drawables: list[_Drawable] = []
        self.planes: list[object] = []   # Plane prims: not framed by the automatic camera
        drawn = (UsdGeom.Tokens.default_, UsdGeom.Tokens.render)
        it = iter(Usd.PrimRange(stage.GetPseudoRoot()))
        for prim in it:
            imageable = UsdGeom.Imageable(prim)
            if imageable and imageable.ComputePurpose() not in drawn:
                it.PruneChildren()
                continue
            if prim.IsA(UsdGeom.PointInstancer):
                self._add_instancer(UsdGeom.PointInstancer(prim))
                it.PruneChildren()  # prototypes are drawn through the instancer
            else:
                d = self._drawable(prim)
                if d is not None:
                    self.drawables.append(d)
                    if prim.IsA(UsdGeom.Plane):
                        self.planes.append(prim)
        self._find_skinned()
        self._skinned_at: tuple[float, dict] = (math.nan, {})
        self.ground_plane = None         # the Plane drawn as the checkered ground, if any
        self.ground_height = self._recorded_ground()
        self._find_ground_plane()

    def _find_skinned(self) -> None:
        """The meshes UsdSkel skins: under a SkelRoot, bound to a skeleton, with joint influences."""
        from pxr import Usd, UsdSkel

        meshes = {d.prim.GetPath(): d for d in self.drawables if d.points is None and d.instancer is None}
        roots = [p for p in self.stage.Traverse() if p.IsA(UsdSkel.Root)]
        for root in roots:
            cache = UsdSkel.Cache()
            cache.Populate(UsdSkel.Root(root), Usd.PrimDefaultPredicate)
            for prim in Usd.PrimRange(root):
                d = meshes.get(prim.GetPath())
                if d is None:
                    continue
                query = cache.GetSkinningQuery(prim)
                skeleton = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
                skel_query = cache.GetSkelQuery(skeleton) if skeleton else None
                if query and skel_query and query.HasJointInfluences():
                    d.skinning = (query, skel_query)

    def _skinned(self, d: _Drawable, time: float, xforms) -> tuple[np.ndarray, np.ndarray] | None:
        """A skinned mesh's points at `time` in its skeleton's space and that space's world
        matrix (row vectors); None when UsdSkel cannot skin it then. Kept for the last time
        asked (bounds and triangles ask for the same frame)."""
        from pxr import Usd, UsdGeom

        if self._skinned_at[0] != time:
            self._skinned_at = (time, {})
        found = self._skinned_at[1]
        path = d.prim.GetPath()
        if path not in found:
            query, skel_query = d.skinning
            code = Usd.TimeCode(time)
            points = UsdGeom.Mesh(d.prim).GetPointsAttr().Get(code)
            ok = points is not None and len(points) > 0 and \
                query.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(code), points, code)
            found[path] = (np.asarray(points, dtype=np.float64),
                           np.array(xforms.GetLocalToWorldTransform(skel_query.GetPrim()))) if ok else None
        return found[path]

    def _recorded_ground(self) -> float | None:
        """The ground height a TOML scene's cache records in its customLayerData."""
        data = self.stage.GetRootLayer().customLayerData.get("simbake", {})
        ground = data.get("ground") if hasattr(data, "get") else None
        if not ground or "height" not in ground:
            return None
        return float(ground["height"])  # along the up axis, which is display space's y

    def _find_ground_plane(self) -> None:
        """A shot's ground: the lowest still Plane facing up (display y), drawn as the checkered
        ground at its height instead of as a quad (at the recorded ground's height, when the
        stage records one)."""
        from pxr import UsdGeom

        xforms = UsdGeom.XformCache(self.stage.GetStartTimeCode())
        best = None
        for prim in self.planes:
            moving = any(UsdGeom.Xformable(p).TransformMightBeTimeVarying()
                         for p in _ancestors(prim) if p.IsA(UsdGeom.Xformable))
            d = next(d for d in self.drawables if d.prim == prim)
            m = np.array(xforms.GetLocalToWorldTransform(prim)) @ self.to_display.T
            normal = d.normals[0] @ np.linalg.inv(m[:3, :3]).T
            normal /= max(np.linalg.norm(normal), 1e-12)
            if moving or abs(normal[1]) < 0.999:
                continue
            height = float(m[3, 1])
            if self.ground_height is not None and abs(height - self.ground_height) > 1e-3 * max(1.0, abs(height)):
                continue
            if best is None or height < best[0]:
                best = (height, prim)
        if best is not None:
            self.ground_height, self.ground_plane = best
            self.drawables = [d for d in self.drawables if d.prim != self.ground_plane]

    def _mesh_drawable(self, prim, **extra) -> _Drawable | None:
        from pxr import UsdGeom

        mesh = UsdGeom.Mesh(prim)
        counts = mesh.GetFaceVertexCountsAttr().Get()
        indices = mesh.GetFaceVertexIndicesAttr().Get()
        if counts is None or indices is None or len(counts) == 0:
            return None
        left = mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded
        corners, faces, slots = _triangulate(np.asarray(counts), np.asarray(indices), left)
        # a shot's cloth is a Mesh with the SimbakeClothAPI, which need not say doubleSided
        double_sided = bool(mesh.GetDoubleSidedAttr().Get()) or "SimbakeClothAPI" in prim.GetAppliedSchemas()
        base = _color(str(prim.GetPath()) if not extra else str(prim.GetName()))
        front, back = (CLOTH_FRONT, CLOTH_BACK) if double_sided else (base, base)
        return _Drawable(prim, corners, faces, slots, front, back, **extra)

    def _drawable(self, prim, **extra) -> _Drawable | None:
        """A Mesh or a gprim (tessellated here, once) to draw; None for anything else."""
        from pxr import UsdGeom

        if prim.IsA(UsdGeom.Mesh):
            return self._mesh_drawable(prim, **extra)
        shape = tessellate(prim)
        if shape is None:
            return None
        points, corners, normals = shape
        color = _color(str(prim.GetPath()) if not extra else str(prim.GetName()))
        n = len(corners)
        return _Drawable(prim, corners, np.arange(n) // 3, np.arange(n), color, color,
                         points=points, normals=normals, **extra)

    def _add_instancer(self, instancer) -> None:
        from pxr import Usd, UsdGeom

        for index, target in enumerate(instancer.GetPrototypesRel().GetTargets()):
            root = self.stage.GetPrimAtPath(target)
            if not root:
                continue
            for prim in Usd.PrimRange(root):
                d = self._drawable(prim, instancer=instancer, prototype=root, proto_index=index)
                if d is not None:
                    self.drawables.append(d)

    # -- per frame -----------------------------------------------------------------------------

    def bounds(self, time: float) -> tuple[np.ndarray, np.ndarray] | None:
        """World bounds (display space) of everything drawn at `time` (but Planes, when there
        is anything else), or None if empty."""
        from pxr import Gf, UsdGeom

        cache = UsdGeom.BBoxCache(time, [UsdGeom.Tokens.default_, UsdGeom.Tokens.render], True)
        box = cache.ComputeWorldBound(self.stage.GetPseudoRoot()).ComputeAlignedRange()
        skinned = [d for d in self.drawables if d.skinning is not None]
        # a 10 m or "infinite" ground, walls: framed is what else is drawn; a skinned mesh's
        # extent is its rest pose's, so it is framed by its skinned points
        if self.planes or skinned:
            framed = Gf.Range3d()
            for prim in {(d.instancer.GetPrim() if d.instancer else d.prim) for d in self.drawables
                         if d.skinning is None}:
                if not prim.IsA(UsdGeom.Plane):
                    framed.UnionWith(cache.ComputeWorldBound(prim).ComputeAlignedRange())
            xforms = UsdGeom.XformCache(time)
            for d in skinned:
                posed = self._skinned(d, time, xforms)
                if posed is not None and len(posed[0]):
                    world = posed[0] @ posed[1][:3, :3] + posed[1][3, :3]
                    framed.UnionWith(Gf.Range3d(Gf.Vec3d(*world.min(axis=0)), Gf.Vec3d(*world.max(axis=0))))
            if not framed.IsEmpty():
                box = framed
        if box.IsEmpty():
            return None
        lo, hi = np.array(box.GetMin()), np.array(box.GetMax())
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        shown = corners @ self.to_display[:3, :3].T
        return shown.min(axis=0), shown.max(axis=0)

    def triangles(self, time: float):
        """Every triangle corner at `time`: positions, normals (display space, float32,
        (3t, 3) each), front and back colours ((3t, 3) float32)."""
        from pxr import UsdGeom

        xforms = UsdGeom.XformCache(time)
        parts = []
        for d in self.drawables:
            to_world = None
            if d.points is not None:  # a gprim: its tessellation
                points, normals = d.points, d.normals
            elif d.skinning is not None:  # posed by UsdSkel, in its skeleton's space
                posed = self._skinned(d, time, xforms)
                if posed is None or len(d.corners) == 0 or d.corners.max() >= len(posed[0]):
                    continue
                points, to_world = posed
                normals = corner_normals(points, d.corners.reshape(-1, 3))
            else:
                mesh = UsdGeom.Mesh(d.prim)
                points = mesh.GetPointsAttr().Get(time)
                if points is None or len(points) == 0 or len(d.corners) == 0:
                    continue
                points = np.asarray(points, dtype=np.float64)
                if d.corners.max() >= len(points):
                    continue  # topology and points disagree: nothing sensible to draw
                normals = self._corner_normals(mesh, d, points, time)
            p = points[d.corners]
            if to_world is not None:
                matrices = [to_world]
            elif d.instancer is None:
                matrices = [np.array(xforms.GetLocalToWorldTransform(d.prim))]
            else:
                matrices = self._instance_matrices(d, xforms, time)
            for m in matrices:
                m = m @ self.to_display.T  # row vectors: p_world = [p 1] m
                pw = p @ m[:3, :3] + m[3, :3]
                nw = normals @ np.linalg.inv(m[:3, :3]).T
                parts.append((pw, nw, d.front, d.back))
        if not parts:
            empty = np.zeros((0, 3), np.float32)
            return empty, empty, empty, empty
        positions = np.concatenate([q[0] for q in parts]).astype(np.float32)
        normals = np.concatenate([q[1] for q in parts])
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0).astype(np.float32)
        front = np.concatenate([np.broadcast_to(np.float32(q[2]), q[0].shape) for q in parts])
        back = np.concatenate([np.broadcast_to(np.float32(q[3]), q[0].shape) for q in parts])
        return positions, normals, front, back

    @staticmethod
    def _corner_normals(mesh, d: _Drawable, points: np.ndarray, time: float) -> np.ndarray:
        """Authored normals per corner (vertex, faceVarying, uniform, constant), else the
        triangle's own (flat) normal."""
        from pxr import UsdGeom

        attr = mesh.GetNormalsAttr()
        normals = attr.Get(time) if attr.HasAuthoredValue() else None
        if normals is not None and len(normals):
            n = np.asarray(normals, dtype=np.float64)
            kind = mesh.GetNormalsInterpolation()
            index = {UsdGeom.Tokens.vertex: d.corners, UsdGeom.Tokens.varying: d.corners,
                     UsdGeom.Tokens.faceVarying: d.face_vertex, UsdGeom.Tokens.uniform: d.face_of_corner,
                     UsdGeom.Tokens.constant: np.zeros_like(d.corners)}.get(kind)
            if index is not None and (len(index) == 0 or index.max() < len(n)):
                return n[index]
        tri = points[d.corners].reshape(-1, 3, 3)
        flat = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return np.repeat(flat, 3, axis=0)

    def _instance_matrices(self, d: _Drawable, xforms, time: float) -> list[np.ndarray]:
        """World matrices (row-vector convention) of a prototype mesh at every instance."""
        indices = d.instancer.GetProtoIndicesAttr().Get(time)
        if indices is None:
            return []
        transforms = d.instancer.ComputeInstanceTransformsAtTime(time, time)
        if not transforms:
            return []
        # the instance transforms include the prototype root's own transform
        mesh_in_proto = np.eye(4) if d.prototype == d.prim else \
            np.array(xforms.ComputeRelativeTransform(d.prim, d.prototype)[0])
        instancer_world = np.array(xforms.GetLocalToWorldTransform(d.instancer.GetPrim()))
        keep = np.asarray(indices) == d.proto_index
        return [mesh_in_proto @ np.array(t) @ instancer_world for t, k in zip(transforms, keep) if k]


# --------------------------------------------------------------------------------------------
# cameras


@dataclass
class Camera:
    view: np.ndarray        # (4, 4) world (display space) -> eye, column vectors
    projection: np.ndarray  # (4, 4) OpenGL clip
    eye: np.ndarray         # (3,) position


def _look_at(eye: np.ndarray, target: np.ndarray, up=np.array([0.0, 1.0, 0.0])) -> np.ndarray:
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = r, u, -f
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def _perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    t = 1.0 / math.tan(fov_y / 2)
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = t / aspect, t
    p[2, 2], p[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    p[3, 2] = -1.0
    return p


def auto_camera(lo: np.ndarray, hi: np.ndarray, aspect: float) -> Camera:
    """A camera looking at the box's centre along VIEW_DIRECTION, as close as it can be with
    every corner of the box inside the picture (and an 8% margin)."""
    center = (lo + hi) / 2
    direction = VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)
    if hi[2] - lo[2] > hi[0] - lo[0]:  # deeper than wide: look from the right instead
        direction = np.array([direction[2], direction[1], -direction[0]])
    view0 = _look_at(center + direction, center)
    right, up, back = view0[0, :3], view0[1, :3], view0[2, :3]
    tan_y = math.tan(FOV_Y / 2) / 1.08
    tan_x = tan_y * aspect
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - center
    # a corner c is inside when |c.right| <= tan_x (d - c.back) and |c.up| <= tan_y (d - c.back)
    d = max(float(np.max(corners @ back + np.abs(corners @ right) / tan_x)),
            float(np.max(corners @ back + np.abs(corners @ up) / tan_y)), 1e-3)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    eye = center + d * direction
    near = max(d - 3 * radius, d * 1e-3)
    return Camera(_look_at(eye, center), _perspective(FOV_Y, aspect, near, d + 40 * radius), eye)


def prim_camera(geometry: CacheGeometry, path: str, time: float, aspect: float, cache: str) -> Camera:
    """The stage's Camera prim at `path`, its picture fitted to `aspect` (the wider of its
    apertures kept)."""
    from pxr import Sdf, UsdGeom

    prim = geometry.stage.GetPrimAtPath(path) if Sdf.Path.IsValidPathString(path) else None
    if not prim or not prim.IsA(UsdGeom.Camera):
        raise SceneError(cache, "--camera", f"{path} is not a Camera prim of the stage")
    cam = UsdGeom.Camera(prim).GetCamera(time)
    world = np.array(cam.transform) @ geometry.to_display.T  # row vectors: camera -> display
    eye = world[3, :3]
    view = np.linalg.inv(world).T
    fov_y = 2 * math.atan(cam.verticalAperture / 2 / cam.focalLength)
    if cam.horizontalAperture / cam.verticalAperture > aspect:  # fit the width
        fov_y = 2 * math.atan(cam.horizontalAperture / aspect / 2 / cam.focalLength)
    near, far = cam.clippingRange.min, cam.clippingRange.max
    return Camera(view, _perspective(fov_y, aspect, max(near, 1e-4), max(far, near * 2)), eye)


# --------------------------------------------------------------------------------------------
# the renderer

_MESH_VS = """#version 330
uniform mat4 u_mvp; uniform mat4 u_light_mvp;
in vec3 in_position; in vec3 in_normal; in vec3 in_front; in vec3 in_back;
out vec3 v_position; out vec3 v_normal; out vec3 v_front; out vec3 v_back; out vec4 v_light;
void main() {
    v_position = in_position; v_normal = in_normal; v_front = in_front; v_back = in_back;
    v_light = u_light_mvp * vec4(in_position, 1.0);
    gl_Position = u_mvp * vec4(in_position, 1.0);
}"""
# the shadow map's look-up, shared by the mesh and ground shaders: 1 lit, 0 in shadow,
# a 3x3 percentage-closer filter over the hardware's 2x2 one
_SHADOW = """
uniform sampler2DShadow u_shadow; uniform float u_bias;
float lit(vec4 light) {
    vec3 p = light.xyz / light.w * 0.5 + 0.5;
    if (p.x < 0.0 || p.x > 1.0 || p.y < 0.0 || p.y > 1.0 || p.z > 1.0) return 1.0;
    vec2 texel = 1.0 / vec2(textureSize(u_shadow, 0));
    float sum = 0.0;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j)
            sum += texture(u_shadow, vec3(p.xy + vec2(i, j) * texel, p.z - u_bias));
    return sum / 9.0;
}"""
# two-sided Lambert: a key light (casting shadows), a fill from the eye, an ambient term
_MESH_FS = """#version 330
uniform vec3 u_light; uniform vec3 u_eye;
in vec3 v_position; in vec3 v_normal; in vec3 v_front; in vec3 v_back; in vec4 v_light;
out vec4 f_color;""" + _SHADOW + """
void main() {
    vec3 n = normalize(v_normal);
    vec3 color = v_front;
    if (!gl_FrontFacing) { n = -n; color = v_back; }
    vec3 to_eye = normalize(u_eye - v_position);
    float key = max(dot(n, u_light), 0.0) * lit(v_light);
    float fill = abs(dot(n, to_eye));
    f_color = vec4(color * (0.22 + 0.58 * key + 0.25 * fill), 1.0);
}"""
_GROUND_VS = """#version 330
uniform mat4 u_mvp; uniform mat4 u_light_mvp;
in vec3 in_position;
out vec3 v_position; out vec4 v_light;
void main() {
    v_position = in_position;
    v_light = u_light_mvp * vec4(in_position, 1.0);
    gl_Position = u_mvp * vec4(in_position, 1.0);
}"""
_GROUND_FS = """#version 330
uniform float u_check; uniform vec3 u_color0; uniform vec3 u_color1; uniform vec3 u_eye;
uniform vec3 u_sky; uniform float u_fade;
in vec3 v_position; in vec4 v_light;
out vec4 f_color;""" + _SHADOW + """
void main() {
    vec2 cell = floor(v_position.xz / u_check);
    vec3 c = mod(cell.x + cell.y, 2.0) < 0.5 ? u_color0 : u_color1;
    c *= 0.6 + 0.4 * lit(v_light);
    float fade = clamp(length(v_position.xz - u_eye.xz) / u_fade, 0.0, 1.0);
    f_color = vec4(mix(c, u_sky, fade * fade), 1.0);
}"""
_DEPTH_VS = """#version 330
uniform mat4 u_light_mvp;
in vec3 in_position;
void main() { gl_Position = u_light_mvp * vec4(in_position, 1.0); }"""
_DEPTH_FS = """#version 330
void main() {}"""


def light_camera(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """An orthographic view from the key light that holds the box (the shadow map's)."""
    center = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    direction = LIGHT_DIRECTION / np.linalg.norm(LIGHT_DIRECTION)
    view = _look_at(center + 2 * radius * direction, center)
    ortho = np.eye(4)
    ortho[0, 0] = ortho[1, 1] = 1.0 / radius
    ortho[2, 2], ortho[2, 3] = -1.0 / (2 * radius), -1.0  # depth 0..4 radius -> -1..1
    return ortho @ view


class Renderer:
    """An offscreen OpenGL context (EGL, Mesa's llvmpipe) that draws frames of one size."""

    def __init__(self, size: tuple[int, int]):
        try:
            import moderngl
        except ImportError:
            raise SceneError("simbake preview", "", f"moderngl is missing: {INSTALL_HINT}") from None
        try:
            self.ctx = moderngl.create_context(standalone=True, backend="egl")
        except Exception as error:  # no libEGL, no Mesa driver
            detail = str(error).splitlines()[0] if str(error) else type(error).__name__
            raise SceneError("simbake preview", "", f"no offscreen OpenGL ({detail}): {INSTALL_HINT}") from None
        self.moderngl = moderngl
        self.size = size
        ctx = self.ctx
        self.mesh_program = ctx.program(vertex_shader=_MESH_VS, fragment_shader=_MESH_FS)
        self.ground_program = ctx.program(vertex_shader=_GROUND_VS, fragment_shader=_GROUND_FS)
        self.depth_program = ctx.program(vertex_shader=_DEPTH_VS, fragment_shader=_DEPTH_FS)
        side = SHADOW_MAPS[0] if max(size) <= 960 else SHADOW_MAPS[1]
        self.shadow = ctx.depth_texture((side, side))
        self.shadow.compare_func = "<="
        self.shadow.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.shadow_fbo = ctx.framebuffer(depth_attachment=self.shadow)
        self.fbo = ctx.framebuffer(ctx.renderbuffer(size, 3, samples=MSAA_SAMPLES),
                                   ctx.depth_renderbuffer(size, samples=MSAA_SAMPLES))
        self.resolved = ctx.framebuffer(ctx.renderbuffer(size, 3))
        self._buffer = None

    def render(self, camera: Camera, triangles, ground_height: float, extent: float,
               light_mvp: np.ndarray) -> np.ndarray:
        """One frame: (h, w, 3) uint8, top row first."""
        mgl = self.moderngl
        ctx = self.ctx
        mvp = (camera.projection @ camera.view).T.astype("f4").tobytes()  # column-major for GL
        light = light_mvp.T.astype("f4").tobytes()
        positions, normals, front, back = triangles
        data = np.hstack([positions, normals, front, back]).astype("f4") if len(positions) else None
        buffer = ctx.buffer(data.tobytes()) if data is not None else None
        # the shadow map: depth from the key light
        self.shadow_fbo.use()
        ctx.enable(mgl.DEPTH_TEST)
        self.shadow_fbo.clear(depth=1.0)
        if buffer is not None:
            self.depth_program["u_light_mvp"].write(light)
            vao = ctx.vertex_array(self.depth_program, [(buffer, "3f 36x", "in_position")])
            vao.render(mgl.TRIANGLES)
            vao.release()
        self.shadow.use(location=0)
        # the ground: a large square under the scene, checks of a round size
        self.fbo.use()
        ctx.clear(*SKY, 1.0, depth=1.0)
        g = self.ground_program
        g["u_mvp"].write(mvp)
        g["u_light_mvp"].write(light)
        g["u_shadow"].value = 0
        g["u_bias"].value = 2e-3
        g["u_check"].value = 10.0 ** math.floor(math.log10(max(extent, 1e-3))) / 2
        g["u_color0"].value, g["u_color1"].value = GROUND_COLORS
        g["u_eye"].value = tuple(camera.eye)
        g["u_sky"].value = SKY
        g["u_fade"].value = 12.0 * max(extent, 1e-3)
        half = 40.0 * max(extent, 1e-3)
        cx, cz = camera.eye[0], camera.eye[2]
        quad = np.array([[cx - half, ground_height, cz - half], [cx + half, ground_height, cz - half],
                         [cx + half, ground_height, cz + half], [cx - half, ground_height, cz - half],
                         [cx + half, ground_height, cz + half], [cx - half, ground_height, cz + half]], "f4")
        ground_buffer = ctx.buffer(quad.tobytes())
        vao = ctx.vertex_array(g, [(ground_buffer, "3f", "in_position")])
        vao.render(mgl.TRIANGLES)
        vao.release()
        ground_buffer.release()
        # the meshes, both sides
        if buffer is not None:
            m = self.mesh_program
            m["u_mvp"].write(mvp)
            m["u_light_mvp"].write(light)
            m["u_shadow"].value = 0
            m["u_bias"].value = 2e-3
            m["u_light"].value = tuple(LIGHT_DIRECTION / np.linalg.norm(LIGHT_DIRECTION))
            m["u_eye"].value = tuple(camera.eye)
            vao = ctx.vertex_array(m, [(buffer, "3f 3f 3f 3f", "in_position", "in_normal", "in_front", "in_back")])
            vao.render(mgl.TRIANGLES)
            vao.release()
            buffer.release()
        ctx.copy_framebuffer(self.resolved, self.fbo)  # resolves the multisampling
        raw = self.resolved.read(components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(self.size[1], self.size[0], 3)[::-1].copy()

    def release(self) -> None:
        self.ctx.release()


# --------------------------------------------------------------------------------------------
# frames


def label_font(size: int):
    """Pillow's default font at `size` pixels (a fixed bitmap font before Pillow 10.1)."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: a fixed bitmap font
        return ImageFont.load_default()


def burn_in(image: np.ndarray, text: str) -> np.ndarray:
    """The text in the top-left corner, white on a dark box, scaled with the image."""
    from PIL import Image, ImageDraw

    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    size = max(10, image.shape[0] // 22)
    font = label_font(size)
    pad = max(3, size // 3)
    left, top, right, bottom = draw.textbbox((2 * pad, 2 * pad), text, font=font)
    draw.rectangle((left - pad, top - pad, right + pad, bottom + pad), fill=(24, 24, 28))
    draw.text((2 * pad, 2 * pad), text, font=font, fill=(255, 255, 255))
    return np.asarray(picture)


class Preview:
    """Renders frames of one cache with one camera setting at one size."""

    def __init__(self, cache: str | Path, size: tuple[int, int], camera: str = "auto"):
        from pxr import Usd

        self.cache = Path(cache)
        check_input_file(self.cache, cache, "")
        try:
            stage = Usd.Stage.Open(str(self.cache))
        except Exception as error:
            detail = str(error).strip().splitlines()[-1] if str(error).strip() else type(error).__name__
            raise SceneError(cache, "", f"cannot open as USD: {detail}") from None
        if stage is None:
            raise SceneError(cache, "", "cannot open as USD")
        self.stage = stage
        self.start = int(math.floor(stage.GetStartTimeCode()))
        self.end = max(self.start, int(math.floor(stage.GetEndTimeCode())))
        self.fps = float(stage.GetTimeCodesPerSecond() or 24.0)
        self.geometry = CacheGeometry(stage)
        self.size = size
        self.camera_choice = camera
        if camera != "auto":
            prim_camera(self.geometry, camera, float(self.start), size[0] / size[1], str(cache))  # checked now
        self._renderer: Renderer | None = None

    def frame_range(self, frames: Sequence[int]) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Bounds over `frames`, their horizontal extent and the ground height."""
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for f in frames:
            b = self.geometry.bounds(float(f))
            if b is not None:
                lo, hi = np.minimum(lo, b[0]), np.maximum(hi, b[1])
        if not np.isfinite(lo).all():
            lo, hi = np.array([-1.0, 0.0, -1.0]), np.array([1.0, 1.0, 1.0])
        ground = self._ground_height()
        if ground is None:
            ground = lo[1] - 0.02 * max(float(np.max(hi - lo)), 1e-3)
        lo[1] = min(lo[1], ground)  # the camera sees where things stand
        extent = float(max(hi[0] - lo[0], hi[2] - lo[2], hi[1] - lo[1], 1e-3))
        return lo, hi, extent, ground

    def _ground_height(self) -> float | None:
        return self.geometry.ground_height

    def frames(self, frames: Sequence[int], label: bool = True) -> Iterator[tuple[int, np.ndarray]]:
        """Renders each frame: (frame, image)."""
        lo, hi, extent, ground = self.frame_range(frames)
        aspect = self.size[0] / self.size[1]
        light_mvp = light_camera(lo, hi)
        if self._renderer is None:
            self._renderer = Renderer(self.size)
        for f in frames:
            time = float(f)
            if self.camera_choice == "auto":
                camera = auto_camera(lo, hi, aspect)
            else:
                camera = prim_camera(self.geometry, self.camera_choice, time, aspect, str(self.cache))
            image = self._renderer.render(camera, self.geometry.triangles(time), ground, extent, light_mvp)
            if label:
                image = burn_in(image, f"frame {f}   {(f - self.start) / self.fps:.3f} s")
            yield f, image

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.release()
            self._renderer = None


def contact_sheet(images: Sequence[np.ndarray], columns: int | None = None, gap: int = 4) -> np.ndarray:
    """Frames in a grid, left to right and top to bottom, on white; one frame alone is just
    that frame (exactly the size asked for)."""
    n = len(images)
    if n == 1:
        return images[0]
    columns = columns or min(n, 4)
    rows = math.ceil(n / columns)
    h, w = images[0].shape[:2]
    sheet = np.full((rows * h + (rows + 1) * gap, columns * w + (columns + 1) * gap, 3), 255, np.uint8)
    for k, image in enumerate(images):
        r, c = divmod(k, columns)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = image
    return sheet


def write_preview(cache: str | Path, output: str | Path | None = None, *, frames: str | None = None,
                  camera: str = "auto", size: tuple[int, int] | None = None) -> tuple[Path, int]:
    """Renders the cache into `output` (.png contact sheet, .mp4 or .gif movie; default
    CACHE.mp4 beside the cache); returns the path and the number of frames drawn."""
    cache = Path(cache)
    out = Path(output) if output is not None else cache.with_suffix(".mp4")
    check_output_path(out, OUTPUT_SUFFIXES, inputs=[cache])
    sheet = out.suffix.lower() == ".png"
    preview = Preview(cache, size or (SHEET_SIZE if sheet else MOVIE_SIZE), camera)
    chosen = parse_frames(frames, preview.start, preview.end, SHEET_FRAMES if sheet else None)
    try:
        if sheet:
            images = [image for _, image in preview.frames(chosen)]
            write_atomically(out, lambda tmp: save_png(tmp, contact_sheet(images)))
        else:
            step = chosen[1] - chosen[0] if len(chosen) > 1 else 1
            write_atomically(out, lambda tmp: _save_movie(tmp, preview.frames(chosen), preview.fps / step))
    finally:
        preview.close()
    return out, len(chosen)


def save_png(path: str, image: np.ndarray) -> None:
    """An RGB image (h, w, 3) uint8 as an optimized PNG."""
    from PIL import Image

    Image.fromarray(image).save(path, format="PNG", optimize=True)


def _save_movie(path: str, frames: Iterator[tuple[int, np.ndarray]], fps: float) -> None:
    """Streams frames into an MP4 (H.264, yuv420p) or a GIF at `fps`."""
    import imageio.v2 as imageio

    if path.lower().endswith(".gif"):
        # GIF frame durations are whole hundredths of a second: 24 fps plays at 25
        writer = imageio.get_writer(path, format="GIF", mode="I", duration=1000.0 / fps, loop=0)
    else:
        writer = imageio.get_writer(path, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                    pixelformat="yuv420p", macro_block_size=2, quality=7,
                                    ffmpeg_log_level="error")
    with writer:
        for _, image in frames:
            writer.append_data(image)
