"""Hydra configs shipped by the HuMoT plugin (``pkg://skelagnostic_humot.conf``)."""
