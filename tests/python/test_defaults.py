"""Every default has one home: the core's structs (WorldSettings, GroundDef, BodyDesc,
ClothDesc, read here through their bindings). The scene's dataclasses (scene.py, which a USD
shot's loader also falls back on) and the SimbakeClothAPI schema's fallbacks (schema.usda and
its generatedSchema.usda) must say the same: a default changed in one place and not in the
others fails here, naming the place and the field."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf

import simbake
from simbake import _core, scene

SCHEMAS = Path(simbake.__file__).parent / "schemas"
SCHEMA_FILES = ("schema.usda", "generatedSchema.usda")

# scene.Cloth's defaulted fields, each with the schema attribute that mirrors it
# (simbake:cloth:<name>); every one is a ClothDesc field of the same name
CLOTH_SCHEMA_NAMES = {
    "area_density": "areaDensity",
    "stretch_stiffness": "stretchStiffness",
    "bend_stiffness": "bendStiffness",
    "damping": "damping",
    "strain_limit": "strainLimit",
    "compression": "compression",
    "friction": "friction",
    "thickness": "thickness",
    "pinned": "pinned",
    "attached": "attached",
    "model": "model",
    "poisson_ratio": "poissonRatio",
    "integrator": "integrator",
    "self_collision": "selfCollision",
}


def dataclass_defaults(cls) -> dict:
    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


def same(a, b) -> bool:
    """Equal as the values they are: numbers exactly (a schema's float attribute at float32),
    sequences element by element."""
    if isinstance(a, (bool, str)) or isinstance(b, (bool, str)):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b
    return list(np.asarray(a).ravel()) == list(np.asarray(b).ravel())


def schema_defaults(name: str) -> dict:
    layer = Sdf.Layer.FindOrOpen(str(SCHEMAS / name))
    prim = layer.GetPrimAtPath("/SimbakeClothAPI")
    assert prim is not None, f"{name}: no SimbakeClothAPI"
    defaults = {}
    for attribute in prim.attributes:
        value = attribute.default
        if attribute.typeName == Sdf.ValueTypeNames.Float:
            value = np.float32(value)
        elif hasattr(value, "__len__") and not isinstance(value, str):
            value = list(value)
        defaults[attribute.name.split(":")[-1]] = value
    return defaults


def test_the_scene_cloth_defaults_are_the_cores():
    core = _core.ClothDesc()
    defaults = dataclass_defaults(scene.Cloth)
    assert set(CLOTH_SCHEMA_NAMES) <= set(defaults), "a scene.Cloth default is not checked here"
    for field in CLOTH_SCHEMA_NAMES:
        assert same(defaults[field], getattr(core, field)), \
            f"scene.Cloth.{field} = {defaults[field]!r}, the core's ClothDesc.{field} = {getattr(core, field)!r}"


@pytest.mark.parametrize("name", SCHEMA_FILES)
def test_the_schema_cloth_defaults_are_the_cores(name):
    core = _core.ClothDesc()
    schema = schema_defaults(name)
    for field, attribute in CLOTH_SCHEMA_NAMES.items():
        assert attribute in schema, f"{name}: simbake:cloth:{attribute} is missing"
        expected = getattr(core, field)
        if isinstance(schema[attribute], np.float32):
            expected = np.float32(expected)  # (the schema's float attributes hold 32 bits)
        assert same(schema[attribute], expected), \
            f"{name}: simbake:cloth:{attribute} = {schema[attribute]!r}, the core's ClothDesc.{field} = {expected!r}"


def test_the_scene_body_and_ground_defaults_are_the_cores():
    body, ground = _core.BodyDesc(), _core.GroundDef()
    body_defaults = dataclass_defaults(scene.Body)
    for field in ("friction", "restitution", "kinematic"):
        assert same(body_defaults[field], getattr(body, field)), \
            f"scene.Body.{field} = {body_defaults[field]!r}, the core's BodyDesc.{field} = {getattr(body, field)!r}"
    ground_defaults = dataclass_defaults(scene.Ground)
    assert set(ground_defaults) == {"height", "friction", "restitution"}
    for field, value in ground_defaults.items():
        assert same(value, getattr(ground, field)), \
            f"scene.Ground.{field} = {value!r}, the core's GroundDef.{field} = {getattr(ground, field)!r}"


def test_the_scene_gravity_is_the_cores():
    gravity = dataclass_defaults(scene.Scene)["gravity"]
    assert same(gravity, _core.WorldSettings().gravity)


def test_a_changed_default_is_caught():
    """The comparison itself: a field set away from its default no longer matches."""
    changed = _core.ClothDesc(friction=0.31)
    assert not same(dataclass_defaults(scene.Cloth)["friction"], changed.friction)
    assert not same(schema_defaults("schema.usda")["friction"], np.float32(changed.friction))
