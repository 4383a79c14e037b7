"""simbake's codeless USD schemas (``schemas/``: plugInfo.json, schema.usda and the
generatedSchema.usda that USD reads), registered with OpenUSD's plugin registry.

USD builds its schema registry once, the first time a stage or a schema is used, so
:func:`register` must run before that; ``import simbake`` calls it. A stage opened before
still reads (simbake finds ``SimbakeClothAPI`` in ``apiSchemas`` itself), but OpenUSD would
not know the schema's attributes or their documentation.
"""

from __future__ import annotations

from pathlib import Path

SCHEMAS_DIR = Path(__file__).resolve().parent / "schemas"
_registered = False


def register() -> None:
    """Register simbake's schema plugin (once; later calls do nothing)."""
    global _registered
    if _registered:
        return
    from pxr import Plug

    Plug.Registry().RegisterPlugins(str(SCHEMAS_DIR))
    _registered = True
