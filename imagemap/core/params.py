"""The engine's parameters: global ones, and a plan of what happens at each pyramid level.

Kept apart from :mod:`imagemap.core.engine` and free of NumPy, so that the command
line and the front ends' configurations can read the choices and defaults without
importing the engine.

Examples
--------
>>> params = EngineParams(levels=uniform_levels((7, 9), final_reseed=0.5))
>>> [(plan.patch_size, plan.final_reseed) for plan in params.level_plans(2)]
[(7, 0.5), (9, 0.0)]
"""

from __future__ import annotations

from dataclasses import dataclass

from imagemap.core.choices import APPEARANCE_PYRAMIDS, BACKENDS, VOTES
from imagemap.validate import check_settings, setting

__all__ = [
    "APPEARANCE_PYRAMIDS",
    "BACKENDS",
    "VOTES",
    "EngineParams",
    "LevelPlan",
    "uniform_levels",
]


@dataclass(frozen=True)
class LevelPlan:
    """What the engine does at one pyramid level.

    A front end states its method level by level here (which levels prefer some
    exemplars, see the coarser levels' colours, reseed from the guide...); the
    engine only carries the plan out.

    Parameters
    ----------
    patch_size : int
        Odd window width.
    max_iterations : int
        EM iterations at most; 0 gives one pass of matching on guide and position
        and one vote.
    exemplar_costs : tuple of float
        Additive cost of matching into each exemplar (empty: none), in the units of
        the window distance: a preference for some exemplars over others.
    context_weights : tuple of float
        The coarser levels' result as extra guide bands, one weight per appearance
        band (empty or all 0: none at this level; a band weighted 0 is left out).
        The query's context is its own synthesised coarser levels, an exemplar's its
        own coarser bands, both brought to the level's grid (collapsed, for
        Laplacian bands). A level's appearance is only its own band, so without
        context a finer level sees nothing of the colours the coarser levels chose
        (the multiresolution neighbourhoods of Wei & Levoy 2000 and Hertzmann et
        al. 2001's image analogies). Ignored at the coarsest level.
    guide_reseed : float
        After the coarser level's matches are propagated, also match on guide and
        position only, and take that match where the propagated one is among the
        worst-fitting ``RESEED_WORST`` of the guide and the new one fits in less
        than this fraction of its distance (0: off). Without it a feature that only
        this level's guide resolves is voted away by the coarser level's appearance.
    final_reseed : float
        After this level's EM, match once more on guide and position only, and take
        that match where the EM's match is among the worst-fitting
        ``FINAL_RESEED_WORST`` of the guide, the new one fits in less than this
        fraction of its distance and carries at least as much appearance detail (a
        reseed may draw a feature, never erase one); 0: off. Where a finer level
        follows, the appearance is voted again so that it starts from these matches.
    position_weight : float, optional
        The position term's weight at this level (None: ``EngineParams.position_weight``).
    final_reseed_any_exemplar : bool
        The final reseed matches without the exemplar costs: where the relief calls for
        a feature, it may come from any exemplar, while the EM keeps each region's
        exemplar.
    patchmatch_passes : int, optional
        PatchMatch passes per search at this level (None:
        ``EngineParams.patchmatch_passes``).
    search_radius : int, optional
        PatchMatch's random search around a match starts at this radius in pixels,
        halving (None: ``EngineParams.search_radius``).
    """

    patch_size: int = setting(7, kind="odd_width")
    max_iterations: int = setting(8, kind="int", minimum=0)
    exemplar_costs: tuple[float, ...] = setting((), kind="floats", minimum=0.0)
    context_weights: tuple[float, ...] = setting((), kind="floats", minimum=0.0)
    guide_reseed: float = setting(0.0, minimum=0.0, below=1.0)
    final_reseed: float = setting(0.0, minimum=0.0, below=1.0)
    position_weight: float | None = setting(None, minimum=0.0, optional=True)
    final_reseed_any_exemplar: bool = setting(False, kind="bool")
    patchmatch_passes: int | None = setting(None, kind="int", minimum=1, optional=True)
    search_radius: int | None = setting(None, kind="int", minimum=1, optional=True)

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def has_context(self) -> bool:
        return any(w > 0 for w in self.context_weights)


@dataclass(frozen=True)
class EngineParams:
    """Parameters of the engine (front ends wrap them in their own configurations).

    What happens at each level is said by ``levels``, one :class:`LevelPlan` per level,
    finest first (:func:`uniform_levels` makes the plans of a method that is the same at
    every level).

    Parameters
    ----------
    levels : tuple of LevelPlan
        The plan per level, finest first (at least one per level synthesized).
    guide_weights, appearance_weights : tuple of float
        One weight per band. With ``normalize_bands`` a weight is per standard
        deviation of its band over the exemplars, so weights are unit-free.
        An appearance weight of 0 carries the band (voted into the output) without
        matching on it.
    position_weight : float
        Weight of the position relative to the mask centroid, in units of the
        mask's RMS radius (0 switches the term off).
    pca_fraction : float
        Fraction of the PCA basis kept, separately for guide and appearance windows.
    pca_max_components : int, optional
        Upper bound on kept components per part.
    pca_samples : int
        Exemplar windows sampled to learn the PCA basis.
    backend : {"patchmatch", "exact", "pynndescent"}
        Nearest-neighbour search of the E-step.
    tolerance : float
        Stop a level when the target decreases by less than this fraction.
    patchmatch_passes : int
        PatchMatch passes per E-step (twice as many from a random start).
    search_radius : int, optional
        PatchMatch's random search around a match starts at this radius in pixels,
        halving down to 1 (None: the exemplar's larger side, the paper's).
    normalize_bands : bool
        Divide each band by its standard deviation over the exemplars.
    guide_padding : {"constant", "reflect", "edge"}
        How guide bands are extended beyond the image (constant = 0, for depth).
    stride : int
        Spacing of query windows; 1 matches every pixel.
    init_from_guide : bool
        At the coarsest level, start from matches on guide and position only.
    window_sigma : float
        Standard deviation of the Gaussian window, as a fraction of its width.
    appearance_pyramid : {"laplacian", "gaussian"}
        What the appearance levels are: Laplacian bands (a level's colours are the
        sum of it and every coarser level) or Gaussian levels. Only the context uses it.
    vote : {"copy", "mean", "mode"}
        The M-step. ``"mean"`` (the paper): every pixel becomes the Gaussian-weighted
        mean of the estimates of the windows that cover it, the exact minimiser of
        the target for fixed matches, which blurs where the estimates disagree.
        ``"copy"``: the same M-step, and from the final matches a copy source
        (:attr:`EngineResult.copy_source`): every pixel's exemplar pixel that most of
        its windows (Gaussian-weighted) agree on, for a front end that copies pixels.
        ``"mode"``: that copy is the M-step of every iteration, so the output is made
        of exemplar pixels and small features survive; a mode M-step that would raise
        the target is refused (the level then stops), so the target still never
        increases.
    quantize_features : bool
        Store the PCA window features as 16-bit integers in one unit per level
        (``_FEATURE_RANGE`` steps cover twice the largest value seen in the PCA
        samples) instead of float32: half the engine's largest arrays. The search
        proposes candidates on them; every accepted match is decided on the exact
        float window distance, so the target still never increases.

    Notes
    -----
    The defaults are the paper's method; each front end sets ``levels``, the weights,
    ``position_weight``, ``pca_fraction``, ``backend``, ``tolerance``, ``vote`` and
    ``appearance_pyramid`` from its own configuration (the depth front end's are
    measured beside :class:`imagemap.depth.config.DepthConfig`'s fields). The others
    were swept on the depth front end (#43; 12 fish/busts at 1x, seed 0, macro part
    transfer; the default 0.814/0.776, seed to seed 0.004/0.014):

    - ``pca_samples`` 4000 -> 0.813/0.785, 16000 -> 0.817/0.785;
    - ``patchmatch_passes`` 2 -> 0.812/0.776, 8 -> 0.815/0.787 (busts' parts in one
      palette 94 % against 99 %);
    - ``window_sigma`` 0.25 -> 0.817/0.767 (a bust's feature not drawn), 0.5 ->
      0.813/0.776;
    - ``init_from_guide`` False -> 0.813/0.787 (parts in one palette 97 % against 99 %);
    - ``quantize_features`` False: the same matches within +-0.003 SSIM for twice the
      features' memory (docs/presets.md, docs/performance.md).

    On the relief plates and scales at 320x240 (seam / rim F1, the default 0.970 / 0.972):
    ``pca_samples`` 4000 -> 0.967/0.969, 16000 -> 0.970/0.971; ``patchmatch_passes`` 2 ->
    0.967/0.969, 8 -> 0.974/0.975; ``window_sigma`` 0.25 -> 0.975/0.973, 0.5 ->
    0.965/0.969; ``init_from_guide`` False -> 0.974/0.970.

    ``guide_padding`` "constant" is the depth's own background (0); ``stride`` 1 and
    ``pca_max_components`` None are the paper's (the BTF front end sets its own).
    """

    levels: tuple[LevelPlan, ...] = (LevelPlan(7), LevelPlan(11), LevelPlan(9))
    guide_weights: tuple[float, ...] = setting((1.0,), kind="floats", minimum=0.0)
    appearance_weights: tuple[float, ...] = setting((1.0,), kind="floats", minimum=0.0)
    position_weight: float = setting(0.0, minimum=0.0)
    pca_fraction: float = setting(0.2, minimum=1e-9, maximum=1.0)
    pca_max_components: int | None = setting(None, kind="int", minimum=1, optional=True)
    pca_samples: int = setting(8000, kind="int", minimum=1)
    backend: str = setting("patchmatch", kind="choice", choices=BACKENDS)
    tolerance: float = setting(2e-3, minimum=0.0)
    patchmatch_passes: int = setting(4, kind="int", minimum=1)
    search_radius: int | None = setting(None, kind="int", minimum=1, optional=True)
    normalize_bands: bool = setting(True, kind="bool")
    guide_padding: str = setting("constant", kind="choice", choices=("constant", "reflect", "edge"))
    stride: int = setting(1, kind="int", minimum=1)
    init_from_guide: bool = setting(True, kind="bool")
    window_sigma: float = setting(1.0 / 3.0, minimum=1e-9)
    vote: str = setting("mean", kind="choice", choices=VOTES)
    quantize_features: bool = setting(True, kind="bool")
    appearance_pyramid: str = setting("laplacian", kind="choice", choices=APPEARANCE_PYRAMIDS)

    def __post_init__(self) -> None:
        check_settings(self)
        if not self.levels or any(not isinstance(plan, LevelPlan) for plan in self.levels):
            raise ValueError("levels must be LevelPlan objects, finest first")

    def level_plans(self, n_levels: int) -> tuple[LevelPlan, ...]:
        """The plans of the ``n_levels`` finest levels (an error when there are fewer)."""
        if len(self.levels) < n_levels:
            raise ValueError(f"{n_levels} levels need {n_levels} level plans")
        return tuple(self.levels[:n_levels])


def uniform_levels(
    patch_sizes: tuple[int, ...],
    *,
    max_iterations: int = 8,
    exemplar_costs: tuple[float, ...] = (),
    context_weights: tuple[float, ...] = (),
    guide_reseed: float = 0.0,
    final_reseed: float = 0.0,
) -> tuple[LevelPlan, ...]:
    """The plans of a method that is the same at every level, finest first.

    One plan per window width of ``patch_sizes``; the context is seen at every level but
    the coarsest (it has no coarser level), the final reseed runs at the finest only.

    Examples
    --------
    >>> [(p.patch_size, p.context_weights) for p in uniform_levels((5, 7), context_weights=(1.0,))]
    [(5, (1.0,)), (7, ())]
    """
    n_levels = len(patch_sizes)
    return tuple(
        LevelPlan(
            patch_size=patch_sizes[level],
            max_iterations=max_iterations,
            exemplar_costs=exemplar_costs,
            context_weights=context_weights if level < n_levels - 1 else (),
            guide_reseed=guide_reseed,
            final_reseed=final_reseed if level == 0 else 0.0,
        )
        for level in range(n_levels)
    )
