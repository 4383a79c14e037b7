"""simbake's version: written into every cache's provenance and shown by `simbake --version`."""

__version__ = "0.1.0"
