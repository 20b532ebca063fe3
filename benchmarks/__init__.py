"""Benchmarks of skelagnostic: ``python benchmarks/run.py --suite NAME``."""
