"""A minimal third-party skelagnostic aligner (entry point ``example``)."""

from skelagnostic.version import distribution_version
from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule

__all__ = ["ExampleAligner", "ExampleDataModule"]
#: Version of the distribution that ships this plugin (its own).
__version__ = distribution_version("skelagnostic-example-aligner")
