"""The Hydra config tree of the ``skelagnostic`` CLI (``pkg://skelagnostic.conf``).

This is the repository's top-level ``conf/`` directory, installed as the package
``skelagnostic.conf`` (``setup.py`` maps it). Groups: ``model/`` (each aligner's
defaults, from its plugin's ``conf/<name>.yaml``), ``data/``, ``trainer/``,
``callbacks/``, ``logger/``, ``experiment/``, ``debug/`` and the optional, git-ignored
``local/``. Plugins add search paths through the ``register_config_paths`` hook.
"""
