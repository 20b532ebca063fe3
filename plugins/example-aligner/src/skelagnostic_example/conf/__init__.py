"""Hydra configs shipped by the example plugin (``pkg://skelagnostic_example.conf``)."""
