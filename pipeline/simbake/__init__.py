"""simbake: bake level sets, rigid bodies and cloth into time-sampled USD caches.

    import simbake
    scene = simbake.load_scene("scene.toml")   # or a USD shot; raises simbake.SceneError on bad input
    stats = simbake.bake(scene, "out.usdc")
    takes = simbake.wedge("scene.toml", {"bodies.ball.restitution": [0.2, 0.5]}, output="w.usda")
"""

from __future__ import annotations

from .errors import SceneError, SimulationError
from .loading import load_scene
from .scene import Scene
from .version import __version__

from .usd_schema import register as _register_usd_schemas

_register_usd_schemas()  # SimbakeClothAPI, before any stage is opened (see usd_schema.py)

__all__ = ["Scene", "SceneError", "SimulationError", "bake", "batch", "load_scene", "wedge", "__version__"]


def bake(scene: Scene, output, **options):
    """Simulate `scene` and write its USD cache to `output`; returns the BakeStats."""
    from .simulate import bake as _bake  # the compiled core loads on first use

    return _bake(scene, output, **options)


def wedge(scene, variations, client=None, **options):
    """Bake every take of `variations` ({"cloths.sheet.stretch_stiffness": [100, 1000]}, x
    `seeds=`) on Dask and gather them into one USD with a variant set `wedge` (`output=`,
    default SCENE.wedge.usda); returns the takes' results (see simbake.wedge_run.wedge)."""
    from .wedge_run import wedge as _wedge  # Dask loads only here

    return _wedge(scene, variations, client, **options)


def batch(scenes, client=None, **options):
    """Bake many scene files on Dask, each as `simbake bake` would (`output_dir=`); returns
    their results (see simbake.wedge_run.batch)."""
    from .wedge_run import batch as _batch

    return _batch(scenes, client, **options)
