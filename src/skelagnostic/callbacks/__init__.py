"""Lightning callbacks of skelagnostic (this package imports lightning)."""

from skelagnostic.callbacks.render import RenderSamples, RenderSampleSource

__all__ = ["RenderSampleSource", "RenderSamples"]
