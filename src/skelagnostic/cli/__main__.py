"""``python -m skelagnostic.cli``: the same as the ``skelagnostic`` console script."""

from skelagnostic.cli import main

raise SystemExit(main())
