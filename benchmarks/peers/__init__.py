"""Rigid bodies against peer engines: the scenes and measures (scenes.py) every runner, the
rigid benchmarks and the tests share."""
