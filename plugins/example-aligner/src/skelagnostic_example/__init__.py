"""A minimal third-party skelagnostic aligner (entry point ``example``)."""

from skelagnostic_example.aligner import ExampleAligner, ExampleDataModule

__all__ = ["ExampleAligner", "ExampleDataModule"]
__version__ = "0.1.0"
