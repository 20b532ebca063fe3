"""The packaged Hydra config tree of the ``skelagnostic`` CLI (``pkg://skelagnostic.conf``).

Groups: ``model/`` (filled by the registered aligners), ``data/``, ``trainer/``,
``callbacks/``, ``logger/`` and ``experiment/``. Plugins add search paths
through the ``register_config_paths`` hook.
"""
