"""Benchmark suites; each module exposes ``run(size: str) -> list[Result]``."""
