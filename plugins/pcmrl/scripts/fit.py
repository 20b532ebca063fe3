r"""``skelagnostic fit`` with the PC-MRL plugin registered from this checkout (not installed).

Same overrides as the CLI, e.g.::

    OMP_NUM_THREADS=1 python plugins/pcmrl/scripts/fit.py model=pcmrl threads=1 \\
        trainer.max_time=00:00:04:30 run_dir=runs/pcmrl_procedural

With ``skelagnostic`` installed (it ships the plugin), ``skelagnostic fit model=pcmrl ...``
is the same; this script also works from a checkout whose package is not installed.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def main(argv: list[str]) -> None:
    """Compose the config from ``argv`` overrides and run it; print the final metrics."""
    import skelagnostic_pcmrl.plugin as plugin

    from skelagnostic.cli import app
    from skelagnostic.plugins import PluginManager

    pm = PluginManager(load_entrypoints=False)
    pm.register(plugin, "pcmrl", version="0.1.0", source="skelagnostic-pcmrl (checkout)")
    task = "fit"
    if argv and argv[0] in app.TASKS:
        task, argv = argv[0], argv[1:]
    cfg = app.compose(argv, task=task, plugin_manager=pm)
    print(json.dumps(app.run(cfg, plugin_manager=pm), indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
