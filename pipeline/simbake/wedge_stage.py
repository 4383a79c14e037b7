"""The stage that gathers a wedge: OUT.usda, one variant per baked take.

    #usda 1.0
    (   customLayerData = { dictionary simbake = { dictionary wedge = {
            string scene, string[] keys, int seeds, string[] takes, string default,
            dictionary failed = { dictionary take_03 = { string label, string error, ... } } } } }
        defaultPrim = "World", upAxis, metersPerUnit, time codes: the takes' own )
    def "World" ( variants = { string wedge = "take_00" }  prepend variantSets = "wedge" )
    {
        variantSet "wedge" = {
            "take_00" ( customData = { dictionary simbake = { string take, string label,
                                       dictionary settings = { double "cloths.sheet.stretch_stiffness" = 100 },
                                       int seed, string cache, string qa, int frames, ... } }
                        prepend references = @./OUT.takes/take_00.usdc@ ) { }
            ...
        }
    }

Each variant references its take's cache (a TOML scene's standalone cache) or its shot stage
(a USD shot's take: the cache layer over the take's override layer over the shot), by a path
relative to OUT.usda; the default variant is the first take that baked. Stage metadata come
from the default take's layer; the time range covers every take. Failed takes have no
variant: they are listed with their one-line errors in the layer's customLayerData.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from .errors import SceneError
from .files import write_atomically
from .wedge_takes import TakeResult, format_value

VARIANT_SET = "wedge"
_METADATA = ("upAxis", "metersPerUnit", "kilogramsPerUnit", "timeCodesPerSecond", "framesPerSecond")


@dataclass
class WedgeStage:
    path: Path
    prim: str                           # the prim holding the variant set: /World
    scene: str
    keys: list[str]
    default: str | None
    takes: list[TakeResult]             # in take order, failed ones included


def _relative(target: Path, folder: Path) -> str:
    rel = os.path.relpath(Path(target).absolute(), Path(folder).absolute())
    return rel if rel.startswith("..") else f"./{rel}"


def _metadata(layer, stages: Sequence[Path]) -> str:
    """The default take's stage metadata, start and end covering every take; returns its
    default prim's name."""
    from pxr import Sdf

    first = Sdf.Layer.FindOrOpen(str(stages[0]))
    for key in _METADATA:
        if first.pseudoRoot.HasInfo(key):
            layer.pseudoRoot.SetInfo(key, first.pseudoRoot.GetInfo(key))
    opened = [Sdf.Layer.FindOrOpen(str(s)) for s in stages]
    layer.startTimeCode = min(o.startTimeCode for o in opened)
    layer.endTimeCode = max(o.endTimeCode for o in opened)
    return first.defaultPrim or "World"


def _usd_value(value: Any) -> Any:
    """A setting as a USD dictionary holds it; what it cannot (a TOML date) as its text."""
    from .usd_values import to_usd

    try:
        return to_usd(value, "settings")
    except TypeError:
        return format_value(value)


def _take_data(record: TakeResult, folder: Path) -> dict:
    from .usd_values import to_usd

    data = {"take": record.name, "label": record.label, "seed": record.seed, **record.figures}
    if record.stage is not None:
        data["stage"] = _relative(record.stage, folder)
    if record.qa is not None:
        data["qa"] = _relative(record.qa, folder)
    if record.error is not None:
        data["error"] = record.error
    data = to_usd(data, "customData")
    data["settings"] = {key: _usd_value(value) for key, value in record.settings.items()}
    return data


def write_wedge_stage(out: Path, scene: str, keys: Sequence[str], seeds: int,
                      records: Sequence[TakeResult]) -> Path:
    """Writes OUT (.usda, or .usdc) beside and renames it; needs at least one baked take."""
    from pxr import Sdf

    from .usd_values import to_usd

    out = Path(out)
    baked = [r for r in records if r.error is None]
    layer = Sdf.Layer.CreateAnonymous(".usda")
    prim_name = _metadata(layer, [r.stage for r in baked])
    layer.defaultPrim = prim_name
    prim = Sdf.PrimSpec(layer.pseudoRoot, prim_name, Sdf.SpecifierDef)
    variants = Sdf.VariantSetSpec(prim, VARIANT_SET)
    for record in baked:
        variant = Sdf.VariantSpec(variants, record.name)
        variant.primSpec.referenceList.Prepend(Sdf.Reference(_relative(record.stage, out.parent)))
        variant.primSpec.customData = {"simbake": _take_data(record, out.parent)}
    prim.variantSetNameList.Prepend(VARIANT_SET)
    prim.variantSelections[VARIANT_SET] = baked[0].name
    failed = {r.name: _take_data(r, out.parent) for r in records if r.error is not None}
    layer.customLayerData = {"simbake": {"wedge": {
        "scene": scene, "keys": to_usd(list(keys), "keys"), "seeds": seeds,
        "takes": to_usd([r.name for r in records], "takes"), "default": baked[0].name, "failed": failed}}}
    fmt = "usdc" if out.suffix.lower() in (".usdc", ".usd") else "usda"

    def export(tmp: str) -> None:
        if not layer.Export(tmp, args={"format": fmt}):
            raise OSError(f"{out}: writing the wedge stage failed")

    write_atomically(out, export)
    return out


def _record(name: str, data: Any, folder: Path) -> TakeResult:
    data = dict(data)
    settings = {k: (list(v) if hasattr(v, "__len__") and not isinstance(v, str) else v)
                for k, v in dict(data.get("settings", {})).items()}
    figures = {k: data[k] for k in ("frames", "wall_seconds", "max_penetration", "warnings") if k in data}
    return TakeResult(name=name, label=str(data.get("label", "")), seed=int(data.get("seed", 0)),
                      settings=settings, error=data.get("error"),
                      stage=(folder / data["stage"]).resolve() if "stage" in data else None,
                      qa=(folder / data["qa"]).resolve() if "qa" in data else None, figures=figures)


def read_wedge_stage(path: str | Path) -> WedgeStage | None:
    """The wedge OUT.usda records, or None when `path` is not a wedge stage (not written by
    simbake wedge); SceneError when it cannot be read at all."""
    from pxr import Sdf, Tf

    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "", "no such file")
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Tf.ErrorException:
        layer = None
    if layer is None:
        raise SceneError(path, "", "cannot open as USD")
    info = dict(layer.customLayerData).get("simbake", {})
    wedge = dict(info).get("wedge") if hasattr(info, "get") else None
    if not wedge:
        return None
    prim = layer.GetPrimAtPath(f"/{layer.defaultPrim}")
    variants = prim.variantSets[VARIANT_SET].variants if prim and VARIANT_SET in prim.variantSets else {}
    failed = dict(wedge.get("failed", {}))
    takes = []
    for name in wedge.get("takes", []):
        if name in variants:
            data = dict(variants[name].primSpec.customData).get("simbake", {})
            takes.append(_record(name, data, path.parent))
        elif name in failed:
            takes.append(_record(name, failed[name], path.parent))
    return WedgeStage(path=path, prim=f"/{layer.defaultPrim}", scene=str(wedge.get("scene", "")),
                      keys=list(wedge.get("keys", [])), default=wedge.get("default"), takes=takes)


def select_take(stage, prim: str, take: str) -> None:
    """Select `take` in the stage's session layer (the file is not changed)."""
    from pxr import Usd

    with Usd.EditContext(stage, stage.GetSessionLayer()):
        stage.GetPrimAtPath(prim).GetVariantSet(VARIANT_SET).SetVariantSelection(take)
