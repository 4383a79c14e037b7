"""Render-ready checks of a USD shot whose cloth meets deforming colliders and is attached to
moving bodies (the shipped assets/scenes/character.usda and flag_carried.usda), apart from the
solver. tests/python/test_character.py runs them on a short range of each shot; this script
bakes a whole shot (or --frames) and checks every frame:

    .venv/bin/python benchmarks/cloth/character_check.py assets/scenes/character.usda [--frames A:B] [-o DIR]

At every baked frame of the `--shot` stage (the cache over the shot):
- inside: every cloth vertex and edge sample (ends and eighths, render_ready.edge_samples)
  against each deforming collider's own mesh at that frame, posed here with OpenUSD alone
  (UsdSkel's skinning and the skeleton's world transform, or the time-sampled points through
  the prim's transform), not through simbake's reading of the shot or the level sets the
  solver used; depth by simbake.qa_deforming.penetration (ray parity, exact nearest
  triangle): none deeper than 1 mm;
- crossings: every cloth of the shot as one mesh, crossings.crossing_count: no pair of
  triangles crossing (a cloth through itself or through another);
- strain: the largest |l| / L - 1 over edges, L from the shot's rest shape, within the
  cloth's strain limit + 1% of it;
- attached: each attached point against where its binding carries it (the binding of
  simbake.qa_attachments, on the surfaces posed here): on a deforming target, bound at the
  first frame to the nearest point of the target's surface (triangle and barycentric
  coordinates), its offset from there kept in that triangle's frame; on a rigid target, fixed
  in the body's frame: within 1 mm;
- through: a deforming collider's edges through cloth triangles (render_ready's predicate):
  none.

Prints a line per failing frame and the worst of each figure; exits 1 when a frame fails.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.cloth.crossings import crossing_count
from benchmarks.cloth.render_ready import edge_samples, largest_strain, mesh_edges, segments_through_mesh
from simbake.qa_attachments import bind_to_mesh, carried_on_mesh

DEEPEST_INSIDE = 1e-3    # (m) a cloth point past a deforming collider's surface
ATTACH_SLACK = 1e-3      # (m) an attached point from where its binding carries it
STRAIN_SLACK = 0.01      # of the strain limit

CHECKS = {
    "inside": "cloth points deeper than 1 mm in a deforming collider (mm)",
    "crossings": "crossing cloth triangle pairs",
    "strain": "strain over the limit + 1% of it",
    "attached": "attached points more than 1 mm from where their binding carries them (mm)",
    "through": "deforming collider edges through cloth triangles",
}


def _triangles(mesh) -> np.ndarray:
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    if not (counts == 3).all():
        raise ValueError(f"{mesh.GetPath()}: the checks read triangle meshes")
    return np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 3)


def _apply(matrix, p: np.ndarray) -> np.ndarray:
    """Points p (n, 3) by a USD (row-vector) matrix."""
    m = np.array(matrix)
    return p @ m[:3, :3] + m[3, :3]


class PosedSurface:
    """A deforming collider's world surface at any frame, posed by OpenUSD alone."""

    def __init__(self, stage, path: str):
        from pxr import Usd, UsdGeom, UsdSkel

        self.prim = stage.GetPrimAtPath(path)
        self.mesh = UsdGeom.Mesh(self.prim)
        self.triangles = _triangles(self.mesh)
        self.skinning = None
        root = UsdSkel.Root.Find(self.prim)
        if root:
            cache = UsdSkel.Cache()
            cache.Populate(root, Usd.PrimDefaultPredicate)
            query = cache.GetSkinningQuery(self.prim)
            skeleton = UsdSkel.BindingAPI(self.prim).GetInheritedSkeleton()
            if query and skeleton and query.HasJointInfluences():
                self.skinning = (cache, query, cache.GetSkelQuery(skeleton))

    def points(self, frame: int) -> np.ndarray:
        from pxr import Usd, UsdGeom

        code = Usd.TimeCode(frame)
        points = self.mesh.GetPointsAttr().Get(code)
        if self.skinning is None:
            return _apply(UsdGeom.Xformable(self.prim).ComputeLocalToWorldTransform(code),
                          np.asarray(points, dtype=np.float64))
        _, query, skel = self.skinning
        if not query.ComputeSkinnedPoints(skel.ComputeSkinningTransforms(code), points, code):
            raise ValueError(f"{self.prim.GetPath()}: UsdSkel cannot skin it at frame {frame}")
        world = UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(code)
        return _apply(world, np.asarray(points, dtype=np.float64))


@dataclass
class Attachment:
    """One cloth's attached points and how the check carries them (the binding of
    simbake.qa_attachments, on the surfaces posed here)."""

    points: np.ndarray                   # (k,) cloth point indices
    target: str                          # the target prim's path
    surface: PosedSurface | None = None  # a deforming target
    bound: tuple | None = None           # its (triangle, barycentric weights, offset) per point
    local: np.ndarray | None = None      # (k, 3) a rigid target: the points in its frame

    def bind(self, stage, frame: int, cloth_points: np.ndarray) -> None:
        from pxr import UsdGeom

        p = cloth_points[self.points]
        if self.surface is not None:
            self.bound = bind_to_mesh(p, self.surface.points(frame), self.surface.triangles)
        else:
            world = UsdGeom.Xformable(stage.GetPrimAtPath(self.target)).ComputeLocalToWorldTransform(frame)
            self.local = _apply(np.linalg.inv(np.array(world)), p)

    def carried(self, stage, frame: int) -> np.ndarray:
        """Where the binding puts the attached points at `frame`."""
        from pxr import UsdGeom

        if self.surface is not None:
            return carried_on_mesh(self.surface.points(frame), self.surface.triangles, *self.bound)
        world = UsdGeom.Xformable(stage.GetPrimAtPath(self.target)).ComputeLocalToWorldTransform(frame)
        return _apply(world, self.local)


@dataclass
class Report:
    """Failures by check: {check: {(cloth, frame): value}}; and each figure's worst over the
    frames, with its frame."""

    failures: dict = field(default_factory=lambda: {name: {} for name in CHECKS})
    worst: dict = field(default_factory=dict)
    frames: int = 0

    def note(self, figure: str, value: float, frame: int) -> None:
        if figure not in self.worst or value > self.worst[figure][0]:
            self.worst[figure] = (value, frame)

    @property
    def failed_frames(self) -> list[int]:
        return sorted({key[-1] for hits in self.failures.values() for key in hits})


def check_shot(shot: str | Path, stage_path: str | Path, scene) -> Report:
    """Every check above at every frame of `scene` (the loaded shot, its range the bake's) on
    the `--shot` stage `stage_path` of its bake."""
    from pxr import Usd, UsdGeom

    from simbake import _core

    source = Usd.Stage.Open(str(shot))
    stage = Usd.Stage.Open(str(stage_path))
    mpu = UsdGeom.GetStageMetersPerUnit(source)
    surfaces = {b.prim_path: PosedSurface(stage, b.prim_path) for b in scene.bodies if b.deformation is not None}
    cloths, sizes = [], []
    for c in scene.cloths:
        prim = source.GetPrimAtPath(c.prim_path)
        mesh = UsdGeom.Mesh(prim)
        triangles = _triangles(mesh)
        edges = mesh_edges(triangles)
        to_world = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode(scene.start_frame))
        rest = _apply(to_world, np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64))
        lengths = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1)
        attach = None
        relation = prim.GetRelationship("simbake:cloth:attachTo")
        indices = prim.GetAttribute("simbake:cloth:attached")
        if relation and relation.GetTargets() and indices and indices.HasAuthoredValue():
            target = str(relation.GetTargets()[0])
            attach = Attachment(np.asarray(indices.Get(), dtype=np.int64), target, surfaces.get(target))
        cloths.append((c, UsdGeom.Mesh(stage.GetPrimAtPath(c.prim_path)), triangles, edges, lengths, attach))
        sizes.append(len(rest))
    report = Report()
    offsets = np.cumsum([0] + sizes)
    all_triangles = np.concatenate([t + offsets[k] for k, (_, _, t, _, _, _) in enumerate(cloths)])
    for frame in range(scene.start_frame, scene.end_frame + 1):
        report.frames += 1
        posed = {path: s.points(frame) for path, s in surfaces.items()}
        everything = []
        for c, mesh, triangles, edges, lengths, attach in cloths:
            code = Usd.TimeCode(frame)
            points = _apply(UsdGeom.Xformable(mesh.GetPrim()).ComputeLocalToWorldTransform(code),
                            np.asarray(mesh.GetPointsAttr().Get(code), dtype=np.float64))
            everything.append(points)
            key = (c.name, frame)
            # strain within the limit
            strain = largest_strain(points, edges, lengths)
            report.note(f"{c.name} strain", strain, frame)
            if c.strain_limit > 0 and strain > c.strain_limit * (1 + STRAIN_SLACK):
                report.failures["strain"][key] = round(strain, 5)
            # cloth inside a deforming collider, and the collider's edges through the cloth
            samples = edge_samples(points, edges)
            for path, vertices in posed.items():
                no_edges = np.zeros((0, 2), dtype=np.int64)
                depth = _core.closed_mesh_depth(vertices, surfaces[path].triangles, samples, no_edges)[0] * mpu
                report.note(f"{c.name} inside {path} (mm)", 1e3 * depth, frame)
                if depth > DEEPEST_INSIDE:
                    report.failures["inside"][key] = round(1e3 * depth, 3)
                through = _edges_through(vertices, surfaces[path].triangles, points, triangles)
                if through:
                    report.failures["through"][key] = through
            # attached points where their binding carries them
            if attach is not None:
                if frame == scene.start_frame:
                    attach.bind(stage, frame, points)
                error = float(np.linalg.norm(points[attach.points] - attach.carried(stage, frame), axis=1).max()) * mpu
                report.note(f"{c.name} attached (mm)", 1e3 * error, frame)
                if error > ATTACH_SLACK:
                    report.failures["attached"][key] = round(1e3 * error, 3)
        count = crossing_count(np.concatenate(everything), all_triangles)
        report.note("crossing pairs", count, frame)
        if count:
            report.failures["crossings"][("all cloths", frame)] = count
    return report


def _edges_through(vertices, body_triangles, points, triangles) -> int:
    """A collider's edges (those near the cloth) through the cloth's triangles."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    edges = mesh_edges(body_triangles)
    a, b = vertices[edges[:, 0]], vertices[edges[:, 1]]
    near = np.all((np.minimum(a, b) <= hi) & (np.maximum(a, b) >= lo), axis=1)
    if not near.any():
        return 0
    return segments_through_mesh(np.stack([a[near], b[near]], axis=1), points, triangles)


def bake_and_check(shot: str | Path, work: Path, start: int | None = None, end: int | None = None,
                   threads: int = 0):
    """Bakes the shot (its range, or start..end) into `work` and checks it: (stats, report)."""
    import simbake

    scene = simbake.load_scene(shot, start_frame=start, end_frame=end)
    stats = simbake.bake(scene, work / f"{Path(shot).stem}.cache.usdc", shot=work / f"{Path(shot).stem}.sim.usda",
                         threads=threads)
    return stats, check_shot(shot, work / f"{Path(shot).stem}.sim.usda", scene)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("shot")
    parser.add_argument("--frames", help="START:END (default: the shot's range)")
    parser.add_argument("-o", "--output", help="a folder to keep the cache and --shot stage in")
    parser.add_argument("--threads", type=int, default=0)
    args = parser.parse_args()
    start, end = (int(x) for x in args.frames.split(":")) if args.frames else (None, None)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.output or tmp)
        work.mkdir(parents=True, exist_ok=True)
        stats, report = bake_and_check(args.shot, work, start, end, args.threads)
    by_frame = {}
    for check, hits in report.failures.items():
        for key, value in hits.items():
            by_frame.setdefault(key[-1], []).append(f"{CHECKS[check]} ({key[0]}): {value}")
    for frame in sorted(by_frame):
        print(f"frame {frame}: " + "; ".join(by_frame[frame]))
    for figure, (value, frame) in sorted(report.worst.items()):
        print(f"worst {figure}: {value:.4g} at frame {frame}")
    print(f"bake {stats.wall_seconds:.1f} s wall for {stats.frames} frames; "
          f"{len(by_frame)} of {report.frames} frames fail")
    return 1 if by_frame else 0


if __name__ == "__main__":
    sys.exit(main())
