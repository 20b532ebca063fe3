"""Lightning callbacks of skelagnostic (this package imports lightning)."""

from skelagnostic.callbacks.checkpoint import LatestWithoutValidation
from skelagnostic.callbacks.render import RenderSamples, RenderSampleSource

__all__ = ["LatestWithoutValidation", "RenderSampleSource", "RenderSamples"]
