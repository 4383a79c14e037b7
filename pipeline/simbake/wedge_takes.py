"""The takes of a wedge: what each one changes in the scene, and its scene made from that.

A wedge varies scene keys (``--set KEY=V1,V2,...``, one or more) and seeds (``--seeds N``);
its takes are the cartesian product, in the order the keys were given, the last key (then
the seed) varying fastest, named ``take_00``, ``take_01``, ... (as many digits as needed).

Keys:

* TOML scenes: a key path of the scene file, tables by name for bodies and cloths:
  ``scene.end_frame``, ``solver.substeps``, ``ground.friction``, ``bodies.ball.restitution``,
  ``bodies.ball.shape.radius``, ``cloths.sheet.stretch_stiffness``, ``cloths.sheet.grid.resolution``.
  A take edits the parsed tables and validates them as the scene file itself is validated
  (simbake.scene.scene_from_data), so a bad value fails with the message a bad file gives.
* USD shots: an attribute ``/PRIM/PATH.ATTRIBUTE`` (``/World/Props/Ball.physics:mass``); the
  prim must exist and the attribute be authored or defined by the prim's schemas. A take
  writes a small override layer (``take_00.over.usda``, beside its cache) that sublayers the
  shot and sets the attribute's default value, and loads that as the shot.

Values are TOML values (``0.2``, ``100``, ``true``, ``[0.0, 1.0, 0.0]``, ``"enforce"``), or a bare
word taken as a string (``enforce``); ``V1,V2`` splits at commas outside brackets and quotes.

Seeds: seed 0 is the scene as the keys leave it. Seed s >= 1 moves every dynamic body and
every cloth by a small, documented perturbation of its initial placement, the same for the
same seed on any machine (drawn from SHA-256, not a random generator whose stream could
change): a horizontal offset of up to POSITION_JITTER along x and along z (Y up; never
towards the ground) and a turn about the vertical through its placement point of up to
YAW_JITTER. Kinematic bodies, the ground and every other setting are left as they are.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from .errors import SceneError
from .loading import is_usd_scene, load_scene
from .scene import TABLE_KEYS, Scene, read_scene_data, scene_from_data

POSITION_JITTER = 1e-3              # m: a seed's largest horizontal offset along x and along z
YAW_JITTER = math.radians(0.5)      # rad: a seed's largest turn about the vertical
MAX_TAKES = 10_000                  # takes in one wedge


@dataclass(frozen=True)
class Take:
    """One bake of a wedge: the values it sets and its seed."""

    name: str                                   # take_00, take_01, ...
    settings: tuple[tuple[str, Any], ...]       # (key, value), in --set order
    seed: int = 0

    def label(self) -> str:
        """'cloths.sheet.stretch_stiffness=100 seed=1': what the take changes, in one line."""
        parts = [f"{key}={format_value(value)}" for key, value in self.settings]
        return " ".join(parts + [f"seed={self.seed}"])


@dataclass
class TakeResult:
    """How one take (or one scene of a batch) ended: baked, or failed with a one-line error."""

    name: str
    label: str                          # what it changes (a batch's scene: "")
    seed: int = 0
    settings: dict = field(default_factory=dict)   # key -> value
    error: str | None = None            # None: baked
    stage: Path | None = None           # what a wedge's variant references (the cache, or a shot's stage)
    cache: Path | None = None
    qa: Path | None = None              # its QA sidecar
    figures: dict = field(default_factory=dict)    # frames, wall_seconds, max_penetration, warnings
    stats: Any = None                   # the BakeStats (None when failed, or read back from a stage)
    worker: str = ""                    # host:pid of the process that baked it

    @property
    def baked(self) -> bool:
        return self.error is None

    def line(self) -> str:
        """One line for the terminal: a take with what it changes, a batch's scene with its cache."""
        what = f" ({self.label})" if self.label else ""
        if self.error is not None:
            return f"{self.name} failed{what}: {self.error}"
        f = self.figures
        return (f"{self.name} baked: {f.get('frames', '?')} frames, {f.get('wall_seconds', 0.0):.2f} s, "
                f"max penetration {f.get('max_penetration', 0.0) * 1e3:.3f} mm"
                + (f", {f['warnings']} QA warning(s)" if f.get("warnings") else "")
                + (what or f" -> {self.cache}"))


def format_value(value: Any) -> str:
    """A value as it would be written after --set KEY= (TOML, strings bare when they can be)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if value and value.replace("_", "").isalnum() else f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {format_value(v)}" for k, v in value.items()) + "}"
    return repr(value) if isinstance(value, float) else str(value)


# --------------------------------------------------------------------------------------
# --set KEY=V1,V2,... and the takes
# --------------------------------------------------------------------------------------

def _split_values(text: str) -> list[str]:
    """'1, [0, 1], "a,b"' -> ['1', '[0, 1]', '"a,b"']: commas outside brackets and quotes."""
    parts, depth, quote, current = [], 0, "", []
    for c in text:
        if quote:
            quote = "" if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
        elif c in "]}":
            depth -= 1
        elif c == "," and depth == 0:
            parts.append("".join(current).strip())
            current = []
            continue
        current.append(c)
    parts.append("".join(current).strip())
    return parts


def parse_value(text: str) -> Any:
    """A TOML value; a bare word that is not one is a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_set(text: str, file: str) -> tuple[str, list[Any]]:
    """'KEY=V1,V2,...' -> (KEY, [V1, V2, ...])."""
    key, sep, values = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SceneError(file, "--set", f"must be KEY=V1,V2,... (e.g. bodies.ball.restitution=0.2,0.5), got {text!r}")
    parts = _split_values(values)
    if any(not p for p in parts):
        raise SceneError(file, f"--set {key}", f"an empty value in {values!r}; give V1,V2,...")
    return key, [parse_value(p) for p in parts]


def plan_takes(variations: Mapping[str, Sequence[Any]], seeds: int, file: str) -> list[Take]:
    """The cartesian product of the keys' values (and seeds 0..seeds-1), named in order."""
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise SceneError(file, "--seeds", f"must be a whole number >= 1, got {seeds!r}")
    for key, values in variations.items():
        if isinstance(values, (str, bytes)) or not isinstance(values, Sequence) or not values:
            raise SceneError(file, f"--set {key}", "needs a list of one or more values")
    combos = list(itertools.product(*[list(v) for v in variations.values()], range(seeds)))
    if len(combos) > MAX_TAKES:
        raise SceneError(file, "--set", f"{len(combos)} takes is more than {MAX_TAKES}; wedge fewer values")
    width = max(2, len(str(len(combos) - 1)))
    keys = list(variations)
    return [Take(f"take_{i:0{width}d}", tuple(zip(keys, combo[:-1])), combo[-1])
            for i, combo in enumerate(combos)]


# --------------------------------------------------------------------------------------
# Key paths of TOML scenes
# --------------------------------------------------------------------------------------

_NAMED = ("bodies", "cloths")
_SUBTABLES = {"bodies": ("shape",), "cloths": ("grid",)}


def _resolve_toml(data: dict, key: str, file: str) -> tuple[dict, str]:
    """The table that holds `key`'s last part, and that part; errors name the key."""
    def fail(problem: str) -> SceneError:
        return SceneError(file, f"--set {key}", problem)

    parts = key.split(".")
    top = parts[0]
    if top in ("scene", "solver", "ground") and len(parts) == 2:
        if top == "ground" and "ground" not in data:
            raise fail("the scene has no [ground]; add one to the file to wedge it")
        table, field, allowed = data.setdefault(top, {}), parts[1], TABLE_KEYS[top]
    elif top in _NAMED and len(parts) in (3, 4):
        table = _named_table(data, top, parts[1], fail)
        field, allowed = parts[2], TABLE_KEYS[top]
        if len(parts) == 4:
            if field not in _SUBTABLES[top]:
                raise fail(f"{field!r} is not a table (tables: {', '.join(_SUBTABLES[top])})")
            if not isinstance(table.get(field), dict):
                raise fail(f"{top[:-1]} {parts[1]!r} has no {field} table")
            table, field, allowed = table[field], parts[3], TABLE_KEYS[f"{top}.{field}"]
    else:
        raise fail("must be scene.KEY, solver.KEY, ground.KEY, bodies.NAME.KEY or cloths.NAME.KEY "
                   "(or bodies.NAME.shape.KEY, cloths.NAME.grid.KEY)")
    if field not in allowed or field == "name":
        raise fail(f"unknown key {field!r} (allowed: {', '.join(k for k in allowed if k != 'name')})")
    return table, field


def _named_table(data: dict, kind: str, name: str, fail) -> dict:
    tables = data.get(kind, [])
    found = [t for t in tables if isinstance(t, dict) and t.get("name") == name] if isinstance(tables, list) else []
    if not found:
        names = [t.get("name") for t in tables if isinstance(t, dict)] if isinstance(tables, list) else []
        listed = ", ".join(str(n) for n in names) or "none"
        raise fail(f"no {kind[:-1] if kind == 'cloths' else 'body'} named {name!r} ({kind}: {listed})")
    return found[0]


def toml_scene(scene_file: str, settings: Iterable[tuple[str, Any]]) -> Scene:
    """The scene file with each (key, value) set, validated as the file itself is."""
    data = copy.deepcopy(read_scene_data(scene_file))
    for key, value in settings:
        table, field = _resolve_toml(data, key, scene_file)
        table[field] = copy.deepcopy(value)
    return scene_from_data(data, scene_file)


# --------------------------------------------------------------------------------------
# Attributes of USD shots
# --------------------------------------------------------------------------------------

def _split_attribute(key: str, file: str) -> tuple[str, str]:
    from pxr import Sdf

    prim, _, name = key.rpartition(".")
    if not key.startswith("/") or not prim or not name or not Sdf.Path.IsValidPathString(prim) \
            or not Sdf.Path.IsValidNamespacedIdentifier(name):
        raise SceneError(file, f"--set {key}", "must be a USD attribute /PRIM/PATH.ATTRIBUTE, "
                                                "e.g. /World/ball.physics:mass")
    return prim, name


def usd_attribute_types(scene_file: str, keys: Iterable[str]) -> dict[str, str]:
    """Each key's attribute type name (authored, or from the prim's schemas) in the shot."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(Path(scene_file).absolute()))
    types = {}
    for key in keys:
        prim_path, name = _split_attribute(key, scene_file)
        prim = stage.GetPrimAtPath(prim_path)
        if not prim:
            raise SceneError(scene_file, f"--set {key}", f"no prim at {prim_path} in the shot")
        attribute = prim.GetAttribute(name)
        if not attribute:
            raise SceneError(scene_file, f"--set {key}",
                             f"{prim_path} has no attribute {name} (authored or in its schemas)")
        types[key] = str(attribute.GetTypeName())
    return types


def _relative(target: Path, folder: Path) -> str:
    """`target` relative to `folder` (./x or ../x), absolute when they share only the root."""
    target, folder = Path(target).absolute(), Path(folder).absolute()
    if os.path.commonpath([target, folder]) == os.path.sep:
        return str(target)
    rel = os.path.relpath(target, folder)
    return rel if rel.startswith("..") else f"./{rel}"


def write_override_layer(path: Path, scene_file: str, settings: Iterable[tuple[str, Any]],
                         types: Mapping[str, str]) -> Path:
    """A layer that sublayers the shot (by a relative path) with the shot's stage metadata and
    each (attribute, value) as an `over` default; written beside and renamed."""
    from pxr import Sdf, Tf

    from .files import write_atomically

    shot = Sdf.Layer.FindOrOpen(str(Path(scene_file).absolute()))
    layer = Sdf.Layer.CreateAnonymous(".usda")
    for info in ("upAxis", "metersPerUnit", "kilogramsPerUnit", "timeCodesPerSecond", "framesPerSecond",
                 "startTimeCode", "endTimeCode", "defaultPrim"):
        if shot.pseudoRoot.HasInfo(info):
            layer.pseudoRoot.SetInfo(info, shot.pseudoRoot.GetInfo(info))
    layer.subLayerPaths.append(_relative(Path(scene_file), Path(path).parent))
    for key, value in settings:
        prim_path, name = _split_attribute(key, scene_file)
        spec = Sdf.CreatePrimInLayer(layer, prim_path)
        attribute = Sdf.AttributeSpec(spec, name, Sdf.ValueTypeNames.Find(types[key]))
        try:
            attribute.default = value
        except (Tf.ErrorException, TypeError, ValueError):
            raise SceneError(scene_file, f"{prim_path}.{name}",
                             f"cannot be set to {format_value(value)} (a {types[key]})") from None
    write_atomically(Path(path), lambda tmp: _export(layer, tmp))
    return Path(path)


def _export(layer, tmp: str) -> None:
    if not layer.Export(tmp, args={"format": "usda"}):
        raise OSError(f"{tmp}: writing the override layer failed")


# --------------------------------------------------------------------------------------
# Seeds
# --------------------------------------------------------------------------------------

def _uniforms(seed: int, kind: str, index: int) -> list[float]:
    """Three numbers in [0, 1) from SHA-256 of (seed, kind, index): the same everywhere."""
    digest = hashlib.sha256(f"simbake-seed:{seed}:{kind}:{index}".encode()).digest()
    return [int.from_bytes(digest[8 * k:8 * k + 8], "little") / 2.0 ** 64 for k in range(3)]


def _jitter(seed: int, kind: str, index: int) -> tuple[np.ndarray, np.ndarray]:
    """(offset (m), quaternion (w, x, y, z) of the yaw) of one object for one seed."""
    u = _uniforms(seed, kind, index)
    offset = np.array([(2 * u[0] - 1) * POSITION_JITTER, 0.0, (2 * u[1] - 1) * POSITION_JITTER])
    half = (2 * u[2] - 1) * YAW_JITTER / 2
    return offset, np.array([math.cos(half), 0.0, math.sin(half), 0.0])


def _qmul(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _yaw_matrix(q: np.ndarray) -> np.ndarray:
    c, s = q[0] ** 2 - q[2] ** 2, 2 * q[0] * q[2]  # cos and sin of the whole angle
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _moved_body(body, seed: int, index: int):
    offset, yaw = _jitter(seed, "body", index)
    return dataclasses.replace(body, position=tuple(float(v) for v in np.add(body.position, offset)),
                               orientation=_qmul(yaw, body.orientation))


def _moved_cloth(cloth, seed: int, index: int):
    offset, yaw = _jitter(seed, "cloth", index)
    if cloth.mesh_vertices is None:  # placed by position and orientation
        return dataclasses.replace(cloth, position=tuple(float(v) for v in np.add(cloth.position, offset)),
                                   orientation=_qmul(yaw, cloth.orientation))
    vertices = np.asarray(cloth.mesh_vertices)  # a USD shot's: world rest positions, about their centre
    centre = vertices.mean(axis=0)
    moved = (vertices - centre) @ _yaw_matrix(yaw).T + centre + offset
    moved.setflags(write=False)
    return dataclasses.replace(cloth, mesh_vertices=moved)


def perturb(scene: Scene, seed: int) -> Scene:
    """The scene with its dynamic bodies and cloths moved by seed's perturbation (seed 0:
    the scene itself)."""
    if seed == 0:
        return scene
    bodies = tuple(b if b.kinematic else _moved_body(b, seed, i) for i, b in enumerate(scene.bodies))
    cloths = tuple(_moved_cloth(c, seed, i) for i, c in enumerate(scene.cloths))
    return dataclasses.replace(scene, bodies=bodies, cloths=cloths)


def perturbable(scene: Scene) -> bool:
    """Whether seeds change anything: a dynamic body or a cloth."""
    return bool(scene.cloths) or any(not b.kinematic for b in scene.bodies)


# --------------------------------------------------------------------------------------
# A take's scene
# --------------------------------------------------------------------------------------

def check_keys(scene_file: str, keys: Sequence[str]) -> dict[str, str]:
    """Refuse, before any bake, a key that names nothing in the scene (exit 2). Returns the
    USD attribute types of a shot's keys (empty for a TOML scene)."""
    if is_usd_scene(scene_file):
        return usd_attribute_types(scene_file, keys)
    data = copy.deepcopy(read_scene_data(scene_file))
    for key in keys:
        _resolve_toml(data, key, scene_file)
    return {}


def take_scene(scene_file: str, take: Take, folder: Path, types: Mapping[str, str]) -> Scene:
    """The validated scene of `take` (a shot's take loads its override layer, written into
    `folder` as TAKE.over.usda); SceneError names the key of a bad value."""
    if is_usd_scene(scene_file):
        override = write_override_layer(Path(folder) / f"{take.name}.over.usda", scene_file,
                                        take.settings, types)
        scene = load_scene(override)
    else:
        scene = toml_scene(scene_file, take.settings)
    return perturb(scene, take.seed)
