"""Hydra search-path plugin: the config trees of skelagnostic's plugins.

Hydra discovers search-path plugins in the ``hydra_plugins`` namespace package.
This one adds the ``register_config_paths`` contributions of every installed
skelagnostic plugin whenever the primary config is skelagnostic's
(``pkg://skelagnostic.conf``), so their groups and options (experiments, data
presets) are part of every composition, including Hydra's ``--help`` listing,
which ignores search paths given on the command line.
"""

from __future__ import annotations

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin

#: The primary config tree this plugin extends.
PRIMARY = "pkg://skelagnostic.conf"
#: Provider name shown by ``--info searchpath``.
PROVIDER = "skelagnostic plugin"


class SkelagnosticSearchPathPlugin(SearchPathPlugin):
    """Appends the installed skelagnostic plugins' config paths to Hydra's search path."""

    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        """Add the plugins' config paths after the primary tree (other apps are left alone).

        Args:
            search_path: Hydra's search path being built.
        """
        present = {element.path for element in search_path.get_path()}
        if PRIMARY not in present:
            return
        from skelagnostic.plugins import get_plugin_manager

        for path in get_plugin_manager().config_paths:
            if path not in present:
                search_path.append(provider=PROVIDER, path=path)
                present.add(path)
