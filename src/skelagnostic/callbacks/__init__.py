"""Lightning callbacks of skelagnostic (this package imports lightning)."""

from skelagnostic.callbacks.checkpoint import LatestWithoutValidation
from skelagnostic.callbacks.ema import EMAWeights
from skelagnostic.callbacks.render import RenderSamples, RenderSampleSource

__all__ = ["EMAWeights", "LatestWithoutValidation", "RenderSampleSource", "RenderSamples"]
