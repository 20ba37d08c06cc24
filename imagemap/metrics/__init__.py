"""Quality of a synthesized image-map against the true one, over the object's mask.

The measures, a module each:

- :mod:`imagemap.metrics.colour`: the results table's colour measures (CIEDE2000,
  luminance SSIM, part accuracy);
- :mod:`imagemap.metrics.features`: detail (small features drawn, part transfer,
  the blur ratio);
- :mod:`imagemap.metrics.coherence`: whether a map holds together, from its source map
  (fragments, seams, palettes per part), and :mod:`imagemap.metrics.continuity`, from
  its pixels (structure continuity, mid-tones);
- :mod:`imagemap.metrics.verdict`: one map's metrics (:class:`ImageMetrics`,
  :func:`image_metrics`) and the faulty verdict (:class:`FaultyRule`,
  :func:`class_reference`).

Every public name is importable from here.

Examples
--------
>>> import numpy as np
>>> truth = np.zeros((20, 20, 3), np.float32); truth[5:15, 5:15] = (0.8, 0.2, 0.1)
>>> mask = truth.any(axis=2)
>>> m = image_metrics(truth, truth, mask)
>>> round(m.ciede2000, 6), round(m.ssim, 6)
(0.0, 1.0)
"""

from imagemap.metrics.coherence import (
    FRAGMENT_COVERAGE,
    FRAGMENT_DRIFT,
    PALETTE_MIN_SHARE,
    FragmentStats,
    PaletteCount,
    coherence_metrics,
    fragment_labels,
    fragments,
    palettes_per_part,
    seam_length,
)
from imagemap.metrics.colour import ciede2000, luminance_ssim, part_accuracy
from imagemap.metrics.continuity import (
    COHERENCE_FLAT,
    CONTINUITY_INTEGRATION,
    CONTINUITY_MIN_SIGMA,
    GRAIN_MIN_SIGMA,
    GRAIN_SCALE,
    MIDTONE_BAND,
    MIDTONE_MIN_CONTRAST,
    MIDTONE_MIN_WINDOW,
    MIDTONE_WINDOW,
    midtone_fraction,
    midtone_share,
    structure_coherence,
    structure_continuity,
)
from imagemap.metrics.features import (
    BLUR_REACH,
    FEATURE_FRACTION,
    FEATURE_MARGIN,
    FEATURE_MIN_PIXELS,
    FEATURE_NCC,
    FEATURE_SHIFT,
    FEATURE_TOLERANCE,
    blur_ratio,
    feature_components,
    feature_correlation,
    feature_transfer,
    features_drawn,
    fine_energy,
    macro_part_transfer,
    source_labels,
)
from imagemap.metrics.verdict import FaultyRule, ImageMetrics, class_reference, image_metrics

__all__ = [
    "BLUR_REACH",
    "COHERENCE_FLAT",
    "CONTINUITY_INTEGRATION",
    "CONTINUITY_MIN_SIGMA",
    "FEATURE_FRACTION",
    "FEATURE_MARGIN",
    "FEATURE_MIN_PIXELS",
    "FEATURE_NCC",
    "FEATURE_SHIFT",
    "FEATURE_TOLERANCE",
    "FRAGMENT_COVERAGE",
    "FRAGMENT_DRIFT",
    "GRAIN_MIN_SIGMA",
    "GRAIN_SCALE",
    "MIDTONE_BAND",
    "MIDTONE_MIN_CONTRAST",
    "MIDTONE_MIN_WINDOW",
    "MIDTONE_WINDOW",
    "PALETTE_MIN_SHARE",
    "FaultyRule",
    "FragmentStats",
    "ImageMetrics",
    "PaletteCount",
    "blur_ratio",
    "ciede2000",
    "class_reference",
    "coherence_metrics",
    "feature_components",
    "feature_correlation",
    "feature_transfer",
    "features_drawn",
    "fine_energy",
    "fragment_labels",
    "fragments",
    "image_metrics",
    "luminance_ssim",
    "macro_part_transfer",
    "midtone_fraction",
    "midtone_share",
    "palettes_per_part",
    "part_accuracy",
    "seam_length",
    "source_labels",
    "structure_coherence",
    "structure_continuity",
]
