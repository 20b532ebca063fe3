"""Lightning callbacks of skelagnostic (this package imports lightning)."""

from skelagnostic.callbacks.checkpoint import FinalStepCheckpoint, LatestWithoutValidation
from skelagnostic.callbacks.ema import EMAWeights
from skelagnostic.callbacks.render import RenderSamples, RenderSampleSource

__all__ = ["EMAWeights", "FinalStepCheckpoint", "LatestWithoutValidation", "RenderSampleSource",
           "RenderSamples"]
