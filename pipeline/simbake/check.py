"""Validate a USD cache: OpenUSD's validators plus simbake's own cache-v1 rules.

``check_cache(path)`` returns a list of one-line problems (empty when the cache is fine):

* OpenUSD's validation framework: every registered validator
  (``ValidationRegistry().GetOrLoadAllValidators()``) is run on the stage. Errors *and*
  warnings are reported (``usd error: ...`` / ``usd warning: ...``): warnings flag things that
  break in some consumers, a cache written by :class:`simbake.usd_writer.CacheWriter` has
  none, so a warning on a simbake cache is worth a look. Pass ``warnings=False`` to keep
  only errors. Info-level findings are never reported.
* A USD shot's cache (version 2: the cache layer, or a ``--shot`` stage composing it over the
  input; its provenance names a USD scene) keeps the input's axes, units and default prim
  (any valid ones), and the every-frame rule below applies to the samples simbake wrote
  (its layers and value clips), not to the input's own animation (a kinematic prop keyed at
  two time codes holds or interpolates between them, as the input says).
* Our rules (DESIGN.md, "USD cache, version 1"):
  - the file exists and opens as a USD stage;
  - stage metadata: ``defaultPrim = "World"`` naming an existing prim, ``upAxis = "Y"``,
    ``metersPerUnit = 1``, ``kilogramsPerUnit = 1``, ``timeCodesPerSecond`` and
    ``framesPerSecond`` both authored and equal, integral ``startTimeCode <= endTimeCode``;
  - every time-sampled attribute has exactly one sample per integer frame from start to end;
  - no NaN or inf in any default or sampled value of a floating-point attribute (points,
    normals, velocities, extent, xformOp:translate, xformOp:orient, ...);
  - every point-based prim has an ``extent`` that contains its points at every frame;
  - every ``xformOp:orient`` quaternion has unit length (within 1e-5).

A USD shot's cache is judged on what simbake authored: OpenUSD's findings whose sites are
prims, properties or layers simbake wrote, and our rules on the attributes and point-based
prims its layers author (an input's own unresolved MDL asset or unauthored extent is the
input's business). ``strict=True`` (``simbake check --strict``) adds every finding of
OpenUSD's validators on the whole composed stage, the input's included.

Problems repeated over many frames are reported once per attribute (count and first frame).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterable

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdValidation, Vt

__all__ = ["check_cache", "UNIT_QUAT_TOL"]

UNIT_QUAT_TOL = 1e-5
_EXTENT_RTOL = 1e-6
# small value type -> its Vt array type: many samples convert to numpy in one C++ call
_ARRAY_OF = {Gf.Vec2d: Vt.Vec2dArray, Gf.Vec3d: Vt.Vec3dArray, Gf.Vec4d: Vt.Vec4dArray,
             Gf.Vec2f: Vt.Vec2fArray, Gf.Vec3f: Vt.Vec3fArray, Gf.Vec4f: Vt.Vec4fArray,
             Gf.Quatd: Vt.QuatdArray, Gf.Quatf: Vt.QuatfArray, Gf.Quath: Vt.QuathArray,
             Gf.Matrix4d: Vt.Matrix4dArray, Gf.Matrix3d: Vt.Matrix3dArray}


def check_cache(path: str | Path, *, warnings: bool = True, strict: bool = False) -> list[str]:
    """Return every problem found in the USD cache at ``path``; empty if it is fine. A shot's
    cache: what simbake authored, and with `strict` what OpenUSD's validators say of the input."""
    path = Path(path)
    if not path.is_file():
        return [f"{path}: no such file" if not path.exists() else f"{path}: not a file"]
    try:
        stage = _open_fresh(path)
    except Exception as exc:  # Tf.ErrorException and friends
        return [f"{path}: cannot open as USD: {_one_line(str(exc))}"]
    if stage is None:
        return [f"{path}: cannot open as USD"]

    problems: list[str] = []
    shot = _is_shot(stage)
    judged = shot and not strict  # only what simbake authored
    problems += _validators(stage, path, warnings, _site_is_ours if judged else None)
    start, end = _metadata(stage, path, problems, shot)
    frames = None
    if start is not None and end is not None:
        frames = np.arange(int(start), int(end) + 1, dtype=np.float64)
    for prim in stage.TraverseAll():
        for attr in prim.GetAttributes():
            if attr.HasAuthoredValue() or attr.GetNumTimeSamples():
                # a shot's own animation (its samples where it put them) is not simbake's to judge
                ours = not shot or _samples_are_ours(attr)
                if judged and not _authored_by_us(attr.GetPropertyStack()):
                    continue  # the input's own value
                _check_attribute(attr, frames if ours else None, path, problems)
        if prim.IsA(UsdGeom.PointBased):
            if judged and not _authored_by_us(UsdGeom.PointBased(prim).GetPointsAttr().GetPropertyStack()):
                continue  # the input's own mesh (its extent is the input's business)
            _check_extent(UsdGeom.PointBased(prim), path, problems)
    return problems


# --------------------------------------------------------------------------------------------

def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _open_fresh(path: Path):
    """Open ``path`` as it is on disk now, even if someone in this process holds the layer."""

    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        if layer.dirty:  # unsaved edits of someone else's: leave them alone, read a copy
            layer = Sdf.Layer.OpenAsAnonymous(str(path))
        else:
            layer.Reload(force=True)
    else:
        layer = Sdf.Layer.FindOrOpen(str(path))
    if layer is None:
        return None
    return Usd.Stage.Open(layer, Usd.Stage.LoadAll)


def _authored_by_us(specs) -> bool:
    """Whether any of these specs (a prim's or property's stack) is in a layer simbake wrote."""
    return any(_ours(spec.layer) for spec in specs)


def _site_is_ours(err) -> bool:
    """A validator finding about something simbake authored: a site on a prim or property with
    an opinion in simbake's layers, or on one of those layers. A finding with no such site
    (a stage-wide one, an input's unresolved asset) is the input's."""
    for site in err.GetSites():
        if site.IsProperty() and _authored_by_us(site.GetProperty().GetPropertyStack()):
            return True
        if site.IsPrim() and site.GetPrim() and not site.GetPrim().IsPseudoRoot() \
                and _authored_by_us(site.GetPrim().GetPrimStack()):
            return True
        layer = site.GetLayer() if hasattr(site, "GetLayer") else None
        if layer is not None and _ours(layer):
            return True
    return False


def _validators(stage, path: Path, warnings: bool, keep=None) -> list[str]:
    from .usd_diagnostics import trapped

    with trapped():  # OpenUSD's own warnings (an unresolved asset) are findings, not stderr
        found = list(_validate(stage))
    return [line for err, line in ((e, _finding(e, path, warnings)) for e in found)
            if line is not None and (keep is None or keep(err))]


def _validate(stage):
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return UsdValidation.ValidationContext(validators).Validate(stage)


def _finding(err, path: Path, warnings: bool) -> str | None:
    kinds = {UsdValidation.ValidationErrorType.Error: "error"}
    if warnings:
        kinds[UsdValidation.ValidationErrorType.Warn] = "warning"
    kind = kinds.get(err.GetType())
    if kind is None:
        return None
    sites = []
    for site in err.GetSites():
        if site.IsProperty():
            sites.append(str(site.GetProperty().GetPath()))
        elif site.IsPrim():
            sites.append(str(site.GetPrim().GetPath()))
    where = f" at {', '.join(sites)}" if sites and sites != ["/"] else ""
    return f"{path}: usd {kind}: {err.GetIdentifier()}{where}: {_one_line(err.GetMessage())}"


def _ours(layer) -> bool:
    """A layer simbake wrote (a cache, a shot's cache layer or one of its clips)."""
    try:
        return "simbake" in dict(layer.customLayerData)
    except Exception:
        return False


def _is_shot(stage) -> bool:
    """A USD shot's cache (version 2): the cache layer itself, or a --shot stage composing it
    over the input; its provenance names a USD scene. Its axes, units and default prim are
    the input's, and the input's own animation is the input's."""
    for layer in stage.GetLayerStack():
        if _ours(layer):
            scene = dict(layer.customLayerData)["simbake"].get("scene", "")
            if str(scene).lower().endswith((".usd", ".usda", ".usdc")):
                return True
    return False


def _samples_are_ours(attr) -> bool:
    """Whether the attribute's time samples come from simbake (its layer or value clips),
    not from the input shot's own animation."""
    info = attr.GetResolveInfo()
    if info.GetSource() == Usd.ResolveInfoSourceValueClips:
        return True
    for spec in attr.GetPropertyStack():
        if spec.HasInfo("timeSamples"):
            return _ours(spec.layer)
    return True


def _metadata(stage, path: Path, problems: list[str], shot: bool = False) -> tuple[float | None, float | None]:

    layer = stage.GetRootLayer()
    dp = stage.GetDefaultPrim()
    if shot:  # the input's axes, units and default prim (any valid ones)
        if layer.HasDefaultPrim() and not dp:
            problems.append(f"{path}: defaultPrim {layer.defaultPrim!r} names no prim")
        if UsdGeom.GetStageUpAxis(stage) not in ("Y", "Z"):
            problems.append(f"{path}: upAxis must be \"Y\" or \"Z\"")
        if not UsdGeom.GetStageMetersPerUnit(stage) > 0:
            problems.append(f"{path}: metersPerUnit must be positive")
        if not UsdPhysics.GetStageKilogramsPerUnit(stage) > 0:
            problems.append(f"{path}: kilogramsPerUnit must be positive")
    else:
        _cache_v1_metadata(stage, layer, dp, path, problems)
    return _time_codes(layer, path, problems)


def _cache_v1_metadata(stage, layer, dp, path: Path, problems: list[str]) -> None:
    if not layer.HasDefaultPrim() or layer.defaultPrim != "World":
        problems.append(f"{path}: defaultPrim must be \"World\", got "
                        f"{layer.defaultPrim if layer.HasDefaultPrim() else 'none'!r}")
    elif not dp:
        problems.append(f"{path}: defaultPrim \"World\" names no prim")
    if not stage.HasAuthoredMetadata("upAxis") or UsdGeom.GetStageUpAxis(stage) != "Y":
        problems.append(f"{path}: upAxis must be \"Y\"")
    if (not stage.HasAuthoredMetadata("metersPerUnit")
            or UsdGeom.GetStageMetersPerUnit(stage) != 1.0):
        problems.append(f"{path}: metersPerUnit must be 1")
    if (not UsdPhysics.StageHasAuthoredKilogramsPerUnit(stage)
            or UsdPhysics.GetStageKilogramsPerUnit(stage) != 1.0):
        problems.append(f"{path}: kilogramsPerUnit must be 1")


def _time_codes(layer, path: Path, problems: list[str]) -> tuple[float | None, float | None]:
    if not layer.HasTimeCodesPerSecond():
        problems.append(f"{path}: timeCodesPerSecond is not set")
    if not layer.HasFramesPerSecond():
        problems.append(f"{path}: framesPerSecond is not set")
    if (layer.HasTimeCodesPerSecond() and layer.HasFramesPerSecond()
            and layer.timeCodesPerSecond != layer.framesPerSecond):
        problems.append(f"{path}: timeCodesPerSecond {layer.timeCodesPerSecond:g} differs from "
                        f"framesPerSecond {layer.framesPerSecond:g}")
    start = layer.startTimeCode if layer.HasStartTimeCode() else None
    end = layer.endTimeCode if layer.HasEndTimeCode() else None
    for name, value in (("startTimeCode", start), ("endTimeCode", end)):
        if value is None:
            problems.append(f"{path}: {name} is not set")
        elif not (math.isfinite(value) and value == int(value)):
            problems.append(f"{path}: {name} must be a whole frame, got {value}")
    if start is None or end is None or start != int(start) or end != int(end):
        return None, None
    if end < start:
        problems.append(f"{path}: endTimeCode {end:g} is before startTimeCode {start:g}")
        return None, None
    return start, end


def _floats(value: Any) -> np.ndarray | None:
    """The floating-point numbers in one USD value, or None if it holds none."""
    if value is None or isinstance(value, (bool, int, str)):
        return None
    if isinstance(value, float):
        return np.array([value])
    if isinstance(value, (Gf.Quatd, Gf.Quatf, Gf.Quath)):
        im = value.GetImaginary()
        return np.array([value.GetReal(), im[0], im[1], im[2]], dtype=np.float64)
    try:
        arr = np.asarray(value)
    except Exception:
        return None
    return arr if arr.dtype.kind == "f" else None


def _bulk(values: list) -> np.ndarray | None:
    """Many samples of one small type (a double3, a quatd...) as one (n, k) array, fast."""
    t = type(values[0])
    if t is float and all(type(v) is float for v in values):
        return np.array(values, dtype=np.float64)[:, None]
    make = _ARRAY_OF.get(t)
    if make is None or not all(type(v) is t for v in values):
        return None
    arr = np.asarray(make(values), dtype=np.float64)  # (quaternions come out as x, y, z, w)
    return arr.reshape(len(values), -1)


def _report(problems, path, attr, what, bad_times: list, total: int) -> None:
    if not bad_times:
        return
    t0 = bad_times[0]
    when = "default value" if t0 is None else f"frame {t0:g}"
    more = f" ({len(bad_times)} of {total} values)" if total > 1 else ""
    problems.append(f"{path}: {attr.GetPath()}: {what} at {when}{more}")


def _check_attribute(attr, frames: np.ndarray | None, path: Path, problems: list[str]) -> None:
    times = attr.GetTimeSamples()  # composed: what a consumer sees
    if times and frames is not None:
        t = np.asarray(times, dtype=np.float64)
        missing = np.setdiff1d(frames, t)
        extra = np.setdiff1d(t, frames)
        if missing.size:
            problems.append(f"{path}: {attr.GetPath()}: {missing.size} frame(s) without a time "
                            f"sample, first {missing[0]:g}")
        if extra.size:
            problems.append(f"{path}: {attr.GetPath()}: {extra.size} time sample(s) outside the "
                            f"whole frames {frames[0]:g}..{frames[-1]:g}, first {extra[0]:g}")

    # values: every authored opinion (default and samples) in every layer, read in bulk
    is_orient = attr.GetName().startswith("xformOp:orient")
    nonfinite: list = []
    nonunit: list = []
    total = 0
    for spec in attr.GetPropertyStack():
        opinions: list[tuple[float | None, Any]] = []
        if spec.HasDefaultValue():
            opinions.append((None, spec.default))
        if spec.HasInfo("timeSamples"):
            samples = spec.GetInfo("timeSamples")
            keep = [(float(k), v) for k, v in sorted(samples.items())
                    if v is not None and not isinstance(v, Sdf.ValueBlock)]
            bulk = _bulk([v for _, v in keep]) if keep else None
            if bulk is not None:
                codes = np.array([k for k, _ in keep])
                total += len(keep)
                finite = np.isfinite(bulk).all(axis=1)
                nonfinite += codes[~finite].tolist()
                if is_orient and bulk.shape[1] == 4:
                    off = np.abs(np.linalg.norm(bulk, axis=1) - 1.0) > UNIT_QUAT_TOL
                    nonunit += codes[finite & off].tolist()
            else:
                opinions += keep
        for code, value in opinions:
            arr = _floats(value)
            if arr is None:
                continue
            total += 1
            if not np.isfinite(arr).all():
                nonfinite.append(code)
            elif is_orient and arr.size % 4 == 0:
                norms = np.linalg.norm(arr.reshape(-1, 4), axis=1)
                if (np.abs(norms - 1.0) > UNIT_QUAT_TOL).any():
                    nonunit.append(code)
    order = lambda c: (-math.inf if c is None else c)  # noqa: E731  default first
    _report(problems, path, attr, "NaN or inf", sorted(nonfinite, key=order), total)
    _report(problems, path, attr, f"quaternion length differs from 1 by more than "
                                  f"{UNIT_QUAT_TOL:g}", sorted(nonunit, key=order), total)


def _check_extent(geom, path: Path, problems: list[str]) -> None:

    points, extent = geom.GetPointsAttr(), geom.GetExtentAttr()
    if not points.HasAuthoredValue():
        return
    if not extent.HasAuthoredValue():
        problems.append(f"{path}: {geom.GetPath()}: points without an authored extent")
        return
    pt, et = set(points.GetTimeSamples()), set(extent.GetTimeSamples())
    # both sampled: compare where both are (a missing sample is reported once, elsewhere)
    times = sorted(pt & et if pt and et else pt | et)
    codes = [Usd.TimeCode(t) for t in times] or [Usd.TimeCode.Default()]
    bad = []
    for code in codes:
        p, e = points.Get(code), extent.Get(code)
        if p is None or len(p) == 0:
            continue
        p = np.asarray(p, dtype=np.float64)
        e = np.asarray(e, dtype=np.float64) if e is not None else np.empty((0, 3))
        if e.shape != (2, 3):
            bad.append(code)
            continue
        if not (np.isfinite(p).all() and np.isfinite(e).all()):
            continue  # reported as NaN/inf already
        tol = _EXTENT_RTOL * max(1.0, float(np.abs(p).max()))
        if (p < e[0] - tol).any() or (p > e[1] + tol).any():
            bad.append(code)
    if bad:
        c = bad[0]
        when = "default value" if c.IsDefault() else f"frame {c.GetValue():g}"
        more = f" ({len(bad)} of {len(codes)} values)" if len(codes) > 1 else ""
        problems.append(f"{path}: {geom.GetPath()}: extent does not contain the points at "
                        f"{when}{more}")
