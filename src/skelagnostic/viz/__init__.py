"""See the results: stick-figure renderings of motions and plots for the methods.

:func:`to_html` writes an interactive 3D viewer (one self-contained HTML page).

Everything here draws headless on matplotlib's Agg canvas (no display, no
pyplot state) and imports matplotlib only when a function is called, so
``import skelagnostic.viz`` stays cheap. It never imports lightning, hydra or
pluggy.
"""

from skelagnostic.viz.camera import Camera
from skelagnostic.viz.html import to_html
from skelagnostic.viz.plots import (
    plot_codebook_usage,
    plot_method_comparison,
    plot_metric_curves,
    plot_phase_manifold,
    plot_phase_over_time,
)
from skelagnostic.viz.render import (
    BODY_GROUP_COLORS,
    Rendering,
    contact_sheet,
    render_contact_sheet,
    render_frames,
    render_motion,
    write_animation,
    write_contact_sheet,
)
from skelagnostic.viz.stick import BODY_GROUPS, RenderError, StickFigure, synchronise

__all__ = [
    "BODY_GROUPS",
    "BODY_GROUP_COLORS",
    "Camera",
    "RenderError",
    "Rendering",
    "StickFigure",
    "contact_sheet",
    "plot_codebook_usage",
    "plot_method_comparison",
    "plot_metric_curves",
    "plot_phase_manifold",
    "plot_phase_over_time",
    "render_contact_sheet",
    "render_frames",
    "render_motion",
    "synchronise",
    "to_html",
    "write_animation",
    "write_contact_sheet",
]
