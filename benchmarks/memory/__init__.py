"""A cloth bake's peak memory against its estimate (cloth_peak.py, shared with the test)."""
