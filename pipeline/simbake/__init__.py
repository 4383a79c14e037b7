"""simbake: bake level sets, rigid bodies and cloth into time-sampled USD caches.

    import simbake
    scene = simbake.load_scene("scene.toml")   # or a USD shot; raises simbake.SceneError on bad input
    stats = simbake.bake(scene, "out.usdc")
"""

from __future__ import annotations

from .errors import SceneError, SimulationError
from .scene import Scene, load_scene

from .usd_schema import register as _register_usd_schemas

_register_usd_schemas()  # SimbakeClothAPI, before any stage is opened (see usd_schema.py)

__version__ = "0.1.0"
__all__ = ["Scene", "SceneError", "SimulationError", "bake", "load_scene", "__version__"]


def bake(scene: Scene, output, **options):
    """Simulate `scene` and write its USD cache to `output`; returns the BakeStats."""
    from .simulate import bake as _bake  # the compiled core loads on first use

    return _bake(scene, output, **options)
