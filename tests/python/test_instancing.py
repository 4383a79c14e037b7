"""--instancing: bodies sharing one shape written as one PointInstancer (simbake.usd_instancer)."""

from __future__ import annotations

import numpy as np
import pytest

import simbake
from simbake.cli import main
from simbake.simulate import INSTANCING_AUTO, instancer_groups
from simbake.usd_instancer import quaternion_rate

from pxr import Usd, UsdGeom, UsdValidation

SCENE = """
[scene]
end_frame = 12
[ground]
[[bodies]]
name = "a"
shape = { type = "sphere", radius = 0.2 }
position = [0.0, 1.0, 0.0]
angular_velocity = [0.0, 3.0, 1.0]
[[bodies]]
name = "b"
shape = { type = "box", size = [0.3, 0.3, 0.3] }
position = [1.0, 1.0, 0.0]
angular_velocity = [2.0, 0.0, 1.0]
linear_velocity = [1.0, 0.0, 0.0]
[[bodies]]
name = "c"
shape = { type = "sphere", radius = 0.2 }
position = [-1.0, 2.0, 0.0]
[[bodies]]
name = "d"
shape = { type = "box", size = [0.3, 0.3, 0.3] }
position = [2.0, 0.5, 1.0]
angular_velocity = [0.0, 4.0, 0.0]
[[bodies]]
name = "e"
shape = { type = "box", size = [0.3, 0.3, 0.5] }
position = [3.0, 0.5, 1.0]
"""


@pytest.fixture(scope="module")
def caches(tmp_path_factory):
    out = tmp_path_factory.mktemp("instancing")
    (out / "scene.toml").write_text(SCENE)
    for mode in ("always", "never", "auto"):
        assert main(["bake", str(out / "scene.toml"), "-o", str(out / f"{mode}.usdc"), "--instancing", mode, "-q"]) == 0
    return out


def _q(quat) -> np.ndarray:
    return np.array([quat.GetReal(), *quat.GetImaginary()], dtype=np.float64)


def test_groups_follow_the_mode(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    scene = simbake.load_scene(tmp_path / "s.toml")
    assert [(g.name, g.bodies) for g in instancer_groups(scene, "always")] == \
        [("sphere_instances", (0, 2)), ("box_instances", (1, 3))]  # "e" is another box size
    assert instancer_groups(scene, "never") == [] and instancer_groups(scene, "auto") == []
    assert INSTANCING_AUTO == 100


def test_instancers_match_the_xforms_they_replace(caches):
    inst, xforms = Usd.Stage.Open(str(caches / "always.usdc")), Usd.Stage.Open(str(caches / "never.usdc"))
    auto = Usd.Stage.Open(str(caches / "auto.usdc"))
    assert auto.GetPrimAtPath("/World/a").IsValid() and not auto.GetPrimAtPath("/World/sphere_instances")
    assert inst.GetPrimAtPath("/World/e").IsValid() and not inst.GetPrimAtPath("/World/a")
    for name, members in (("sphere_instances", ["a", "c"]), ("box_instances", ["b", "d"])):
        pi = UsdGeom.PointInstancer(inst.GetPrimAtPath(f"/World/{name}"))
        assert list(pi.GetPrim().GetAttribute("simbake:names").Get()) == members
        assert list(pi.GetIdsAttr().Get()) == [["a", "b", "c", "d", "e"].index(m) for m in members]
        assert list(pi.GetProtoIndicesAttr().Get()) == [0, 0]
        assert [str(t) for t in pi.GetPrototypesRel().GetTargets()] == [f"/World/{name}/Prototypes/mesh"]
        for attr in (pi.GetPositionsAttr(), pi.GetOrientationsAttr(), pi.GetVelocitiesAttr(),
                     pi.GetAngularVelocitiesAttr(), pi.GetExtentAttr()):
            assert attr.GetTimeSamples() == [float(f) for f in range(1, 13)], attr.GetName()
        for frame in range(1, 13):
            positions = np.array(pi.GetPositionsAttr().Get(frame), dtype=np.float64)
            orientations = np.array([_q(q) for q in pi.GetOrientationsAttr().Get(frame)])
            assert positions.shape == (2, 3) and orientations.shape == (2, 4)
            assert len(pi.GetVelocitiesAttr().Get(frame)) == len(pi.GetAngularVelocitiesAttr().Get(frame)) == 2
            for k, m in enumerate(members):
                prim = xforms.GetPrimAtPath(f"/World/{m}")
                t = np.array(prim.GetAttribute("xformOp:translate").Get(frame))
                q = _q(prim.GetAttribute("xformOp:orient").Get(frame))
                np.testing.assert_allclose(positions[k], t, atol=1e-6)  # point3f
                # quath: half precision, 2^-11 relative per component
                assert min(np.abs(orientations[k] - q).max(), np.abs(orientations[k] + q).max()) < 1e-3
            # every instance inside the extent
            lo, hi = np.array(pi.GetExtentAttr().Get(frame), dtype=np.float64)
            assert (positions >= lo - 1e-6).all() and (positions <= hi + 1e-6).all()


def test_instance_velocities_are_the_motion_over_the_frame(caches):
    """velocities and angularVelocities (degrees per second, as USD specifies) against finite
    differences of the Xform-per-body cache's positions and orientations (double precision)."""
    inst, xforms = Usd.Stage.Open(str(caches / "always.usdc")), Usd.Stage.Open(str(caches / "never.usdc"))
    spun = 0.0
    for name, members in (("sphere_instances", ["a", "c"]), ("box_instances", ["b", "d"])):
        pi = UsdGeom.PointInstancer(inst.GetPrimAtPath(f"/World/{name}"))
        for frame in range(1, 12):
            v = np.array(pi.GetVelocitiesAttr().Get(frame), dtype=np.float64)
            w = np.array(pi.GetAngularVelocitiesAttr().Get(frame), dtype=np.float64)
            for k, m in enumerate(members):
                prim = xforms.GetPrimAtPath(f"/World/{m}")
                t0, t1 = (np.array(prim.GetAttribute("xformOp:translate").Get(f)) for f in (frame, frame + 1))
                q0, q1 = (_q(prim.GetAttribute("xformOp:orient").Get(f)) for f in (frame, frame + 1))
                np.testing.assert_allclose(v[k], (t1 - t0) * 24, rtol=1e-6, atol=1e-5)  # vector3f
                # q1 = exp(w dt / 2) q0: turning q0 by the angular velocity for a frame gives q1
                expected = np.degrees(quaternion_rate(q0[None], q1[None], 1 / 24)[0])
                np.testing.assert_allclose(w[k], expected, rtol=1e-5, atol=1e-3)
                angle = np.radians(np.linalg.norm(w[k])) / 24
                axis = w[k] / (np.linalg.norm(w[k]) or 1)
                turn = np.array([np.cos(angle / 2), *(np.sin(angle / 2) * axis)])
                a, b = turn, q0
                turned = np.array([a[0] * b[0] - a[1:] @ b[1:], *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))])
                assert min(np.abs(turned - q1).max(), np.abs(turned + q1).max()) < 1e-6
                spun = max(spun, np.linalg.norm(w[k]))
    assert spun > 100  # degrees per second: the test saw real spin


def test_instanced_cache_is_valid(caches):
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    errors = context.Validate(Usd.Stage.Open(str(caches / "always.usdc")))
    assert [e.GetMessage() for e in errors] == []
    assert main(["check", str(caches / "always.usdc")]) == 0
