"""The cloth drape against peer engines (drape_spec.py, the runners), and the checks of layers
through layers (crossings.py) and of render-ready caches (render_ready.py) the tests share."""
