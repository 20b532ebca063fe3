"""Lightning callbacks of skelagnostic (this package imports lightning)."""

from skelagnostic.callbacks.checkpoint import (
    FinalStepCheckpoint,
    FinalStepValidation,
    LatestWithoutValidation,
    newest_checkpoint,
)
from skelagnostic.callbacks.checkpoint_io import AtomicCheckpointIO
from skelagnostic.callbacks.ema import EMAWeights
from skelagnostic.callbacks.fit_summary import (
    QUICK_BELOW_STEPS,
    SUMMARY_MODES,
    FitSummary,
    SummaryContent,
    summary_mode,
)
from skelagnostic.callbacks.interrupt import ResumeHint
from skelagnostic.callbacks.log_interval import AdaptiveLogInterval
from skelagnostic.callbacks.loggers import LocalMLFlowLogger, log_image
from skelagnostic.callbacks.nonfinite import NonFiniteTrainingError, StopOnNonFinite
from skelagnostic.callbacks.progress import RichProgress
from skelagnostic.callbacks.render import RenderSamples, RenderSampleSource
from skelagnostic.callbacks.resume import ResumeFromEpochEnd
from skelagnostic.callbacks.split import SPLIT_FILE, RecordSplit
from skelagnostic.callbacks.stopping import StopReason, stop_reason

__all__ = [
    "QUICK_BELOW_STEPS",
    "SPLIT_FILE",
    "SUMMARY_MODES",
    "AdaptiveLogInterval",
    "AtomicCheckpointIO",
    "EMAWeights",
    "FinalStepCheckpoint",
    "FinalStepValidation",
    "FitSummary",
    "LatestWithoutValidation",
    "LocalMLFlowLogger",
    "NonFiniteTrainingError",
    "RecordSplit",
    "RenderSampleSource",
    "RenderSamples",
    "ResumeFromEpochEnd",
    "ResumeHint",
    "RichProgress",
    "StopOnNonFinite",
    "StopReason",
    "SummaryContent",
    "log_image",
    "newest_checkpoint",
    "stop_reason",
    "summary_mode",
]
