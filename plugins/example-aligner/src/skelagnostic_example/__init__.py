"""A minimal third-party skelagnostic aligner (entry point ``example``).

The classes are imported on first access (``skelagnostic.lazy``): loading the plugin
for ``skelagnostic plugins`` or ``--help`` imports neither them nor Lightning.
"""

from typing import TYPE_CHECKING

from skelagnostic.lazy import lazy_exports
from skelagnostic.version import distribution_version

__all__ = ["ExampleAligner", "ExampleDataModule"]
#: Version of the distribution that ships this plugin (its own).
__version__ = distribution_version("skelagnostic-example-aligner")

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "ExampleAligner": "skelagnostic_example.aligner",
        "ExampleDataModule": "skelagnostic_example.aligner",
    },
)

if TYPE_CHECKING:  # pragma: no cover
    from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule
