"""Values into USD dictionaries, shared by every writer of layer data (the cache writers,
shot layers, clips and wedge stages): Python, numpy and path values converted to what a USD
dictionary (``customLayerData``, ``customData``) stores faithfully, and nested dictionaries
merged key by key."""

from __future__ import annotations

import os
from typing import Any, Mapping

import numpy as np
from pxr import Vt

__all__ = ["merge_into", "to_usd"]


def to_usd(value: Any, where: str) -> Any:
    """Convert a provenance value to something a USD dictionary stores faithfully."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, int):
        return value if -2**63 <= value < 2**63 else str(value)
    if isinstance(value, float):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, Mapping):
        return {str(k): to_usd(v, f"{where}.{k}") for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        items = [v.item() if isinstance(v, np.generic) else v for v in value]
        if all(isinstance(v, str) for v in items):
            return Vt.StringArray(items)
        if all(isinstance(v, bool) for v in items):
            return Vt.BoolArray(items)
        if all(isinstance(v, int) and not isinstance(v, bool) for v in items):
            if all(-2**63 <= v < 2**63 for v in items):
                return Vt.Int64Array(items)
        elif all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
            return Vt.DoubleArray([float(v) for v in items])
        # mixed or nested lists: a dictionary keyed by position keeps every value readable
        return {f"{i:04d}": to_usd(v, f"{where}[{i}]")
                for i, v in enumerate(items) if v is not None}
    raise TypeError(f"provenance {where}: cannot store a {type(value).__name__} in USD")


def merge_into(into: dict, data: Mapping) -> None:
    """Merge `data` into `into` in place: nested mappings key by key (copied, never shared),
    any other value replaced."""
    for key, value in data.items():
        if isinstance(value, Mapping) and isinstance(into.get(key), Mapping):
            into[key] = dict(into[key])
            merge_into(into[key], value)
        else:
            into[key] = value
