"""MuJoCo on one peer-benchmark scene; prints one JSON line.

    benchmarks/peers/.venv-peers/bin/python benchmarks/peers/run_mujoco.py SCENE [--seconds S]

Settings (MuJoCo 4.0.0, Z up: scenes are converted from Y up):
- time step 1/504 s (21 steps per 1/24 s frame; MuJoCo's default is 0.002 s, which does not
  divide a frame), default integrator (Euler), solver (Newton), pyramidal friction cones,
  condim 3 (sliding friction only), default solimp;
- MuJoCo combines the friction of a pair by max, so every geom (and the floor plane) gets mu;
  torsional and rolling friction at MuJoCo's defaults (0.005, 0.0001) do nothing with condim 3;
- no restitution coefficient in MuJoCo: contacts are spring-dampers set by solref
  (timeconst, dampratio). e = 0 scenes keep the default (0.02 s, 1, critically damped).
  The sphere drop gets the damping ratio of a linear spring-damper whose coefficient of
  restitution is e: zeta = -ln e / sqrt(pi^2 + ln^2 e) = 0.2155 for e = 0.5, timeconst 0.02 s;
- boxes and spheres as primitive geoms with the scene's mass (inertia from the shape);
  the ground is an infinite plane.
Only mj_step is timed (the model is compiled before the clock starts).
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenes  # noqa: E402

import mujoco  # noqa: E402

STEPS_PER_FRAME = 21
TIME_STEP = 1.0 / (scenes.FPS * STEPS_PER_FRAME)
TIMECONST = 0.02


def damping_ratio_for_restitution(e: float) -> float:
    if e <= 0.0:
        return 1.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi ** 2 + ln ** 2)


def model_xml(scene: scenes.Scene) -> tuple[str, dict]:
    mu = scenes.per_object(scene.mu, "max")
    zeta = damping_ratio_for_restitution(scene.e)
    solref = f"{TIMECONST} {zeta:.6f}"
    gx, gy, gz = scenes.vec_to_zup(scene.gravity)
    memory = max(16, 2 * len(scene.bodies) // 10 + 16)   # MB of the arena (contacts, solver)
    lines = [
        '<mujoco model="peer">',
        f'  <option timestep="{TIME_STEP!r}" gravity="{gx!r} {gy!r} {gz!r}"/>',
        f'  <size memory="{memory}M"/>',
        f'  <default><geom friction="{mu} 0.005 0.0001" condim="3" solref="{solref}"/></default>',
        '  <worldbody>',
        f'    <geom name="ground" type="plane" size="0 0 1" pos="0 0 {scene.ground_height!r}"/>',
    ]
    for i, b in enumerate(scene.bodies):
        pos = " ".join(repr(float(v)) for v in scenes.vec_to_zup(b.position))
        quat = " ".join(repr(float(v)) for v in scenes.quat_to_zup(b.orientation))
        if b.shape == "box":
            geom = f'type="box" size="{0.5 * b.size[0]!r} {0.5 * b.size[1]!r} {0.5 * b.size[2]!r}"'
        else:
            geom = f'type="sphere" size="{b.radius!r}"'
        lines.append(f'    <body name="b{i}" pos="{pos}" quat="{quat}"><freejoint/>'
                     f'<geom {geom} mass="{b.mass!r}"/></body>')
    lines += ['  </worldbody>', '</mujoco>']
    settings = {
        "time_step": TIME_STEP, "steps_per_frame": STEPS_PER_FRAME, "integrator": "Euler (default)",
        "solver": "Newton (default)", "cone": "pyramidal (default)", "condim": 3,
        "friction_per_geom": mu, "combine": "max (MuJoCo)",
        "solref": [TIMECONST, zeta], "solref_note": ("damping ratio from e (linear spring-damper)"
                                                     if scene.e > 0 else "default (0.02 s, critically damped)"),
        "solimp": "default (0.9 0.95 0.001 0.5 2)", "arena_memory_mb": memory,
    }
    return "\n".join(lines), settings


def main() -> None:
    args = scenes.common_args()
    scene = scenes.build(args.scene, args.seconds)
    xml, settings = model_xml(scene)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)

    def centres():
        return scenes.positions_from_zup(data.xpos[1:].copy())

    def turns():
        return scenes.orientations_from_zup(data.xquat[1:].copy())

    record = set(scene.recorded_frames())
    positions, orientations = [centres()], [turns()]
    clock = scenes.StepClock()
    max_contacts = 0
    for frame in range(1, scene.frames + 1):
        with clock:
            mujoco.mj_step(model, data, nstep=STEPS_PER_FRAME)
        max_contacts = max(max_contacts, int(data.ncon))
        if frame in record:
            positions.append(centres())
            orientations.append(turns())
    warnings = {str(mujoco.mjtWarning(i)).split(".")[-1]: int(w.number)
                for i, w in enumerate(data.warning) if w.number}
    print(json.dumps(scenes.result("mujoco", mujoco.__version__, scene, clock,
                                   np.array(positions), settings,
                                   {"max_contacts_at_frame_ends": max_contacts, "mujoco_warnings": warnings},
                                   np.array(orientations))))


if __name__ == "__main__":
    main()
