"""Hydra configs of the vqpae plugin (``pkg://skelagnostic_vqpae.conf``)."""
