"""Hydra configs of the PC-MRL plugin (``pkg://skelagnostic_pcmrl.conf``)."""
