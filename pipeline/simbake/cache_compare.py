"""Two caches compared by content: every spec, every field and every time sample, bit for bit.

Each cache is opened with Sdf and its layer compared: the layer metadata a cache holds (default
prim, time codes, frame rate, sublayers), the spec paths, every field of every spec, and every
time sample (arrays by their bytes). The layer's customLayerData is compared except the
provenance (simbake's version, the scene's name and hash, the solver settings), which may
differ between builds of the same scene. `.usdc` files of the same content may be laid out
differently, so equal bytes are not required (nor enough to say where two caches differ).

Used to hold a bake to the same cache across thread counts, worker machines and refactors
(benchmarks/same_bits.py, the wedge tests).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["PROVENANCE", "first_difference"]

# the customLayerData["simbake"] keys left out of the comparison
PROVENANCE = ("version", "scene", "scene_sha256", "solver")


def _plain(value):
    """A field or sample value as something == compares exactly (arrays by their bytes)."""
    if hasattr(value, "__len__") and type(value).__module__.startswith("pxr"):
        try:
            array = np.asarray(value)
            if array.dtype != object:
                return (array.dtype.str, array.shape, array.tobytes())
        except (TypeError, ValueError):
            pass
    return value


def _layer_data(layer) -> dict:
    data = dict(layer.customLayerData)
    simbake = dict(data.get("simbake", {}))
    for key in PROVENANCE:
        simbake.pop(key, None)
    data["simbake"] = simbake
    return data


def first_difference(path_a: str | Path, path_b: str | Path) -> str | None:
    """The first difference between two caches' content, in words (``"/World/sheet.points:
    sample at 12.0 differs"``), or None when they hold the same."""
    from pxr import Sdf

    a, b = Sdf.Layer.FindOrOpen(str(path_a)), Sdf.Layer.FindOrOpen(str(path_b))
    if _layer_data(a) != _layer_data(b):
        return "customLayerData differs"
    for key in ("defaultPrim", "startTimeCode", "endTimeCode", "timeCodesPerSecond", "framesPerSecond",
                "subLayerPaths"):
        if _plain(a.pseudoRoot.GetInfo(key) if a.pseudoRoot.HasInfo(key) else None) != \
           _plain(b.pseudoRoot.GetInfo(key) if b.pseudoRoot.HasInfo(key) else None):
            return f"layer metadata {key} differs"
    paths_a, paths_b = [], []
    a.Traverse(Sdf.Path.absoluteRootPath, paths_a.append)
    b.Traverse(Sdf.Path.absoluteRootPath, paths_b.append)
    if sorted(map(str, paths_a)) != sorted(map(str, paths_b)):
        only = sorted(set(map(str, paths_a)) ^ set(map(str, paths_b)))
        return f"spec paths differ: {only[:5]}"
    for path in paths_a:
        if path == Sdf.Path.absoluteRootPath:
            continue
        spec_a, spec_b = a.GetObjectAtPath(path), b.GetObjectAtPath(path)
        if spec_a is None or spec_b is None:  # a target or connection path: its owner compares it
            if (spec_a is None) != (spec_b is None):
                return f"{path}: a spec in one cache only"
            continue
        keys = sorted(set(spec_a.ListInfoKeys()) | set(spec_b.ListInfoKeys()))
        for key in keys:
            if key == "timeSamples":
                continue
            if _plain(spec_a.GetInfo(key)) != _plain(spec_b.GetInfo(key)):
                return f"{path}: field {key} differs"
        if isinstance(spec_a, Sdf.AttributeSpec):
            times = a.ListTimeSamplesForPath(path)
            if list(times) != list(b.ListTimeSamplesForPath(path)):
                return f"{path}: time codes differ"
            for t in times:
                if _plain(a.QueryTimeSample(path, t)) != _plain(b.QueryTimeSample(path, t)):
                    return f"{path}: sample at {t} differs"
    return None
