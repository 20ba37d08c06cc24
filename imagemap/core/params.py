"""The engine's parameters: global ones, and a plan of what happens at each pyramid level.

Kept apart from :mod:`imagemap.core.engine` and free of NumPy, so that the command
line and the front ends' configurations can read the choices and defaults without
importing the engine.

Examples
--------
>>> params = EngineParams(patch_sizes=(7, 9), final_reseed=0.5)
>>> [(plan.patch_size, plan.final_reseed) for plan in params.level_plans(2)]
[(7, 0.5), (9, 0.0)]
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["APPEARANCE_PYRAMIDS", "BACKENDS", "VOTES", "EngineParams", "LevelPlan"]

#: Nearest-neighbour searches of the E-step (:mod:`imagemap.core.search`).
BACKENDS = ("patchmatch", "exact", "pynndescent")
#: The engine's M-steps: Gaussian-weighted mean, or the weighted mode (a copy).
VOTES = ("mean", "mode")
#: What the appearance bands of a level are: its Gaussian level or its Laplacian band.
APPEARANCE_PYRAMIDS = ("gaussian", "laplacian")


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
    """

    patch_size: int
    max_iterations: int = 8
    exemplar_costs: tuple[float, ...] = ()
    context_weights: tuple[float, ...] = ()
    guide_reseed: float = 0.0
    final_reseed: float = 0.0
    position_weight: float | None = None
    final_reseed_any_exemplar: bool = False

    def __post_init__(self) -> None:
        if self.position_weight is not None and not self.position_weight >= 0:
            raise ValueError("position_weight must be >= 0")
        if self.patch_size < 1 or self.patch_size % 2 == 0:
            raise ValueError(f"patch size must be odd and positive, got {self.patch_size}")
        if self.max_iterations < 0:
            raise ValueError("max_iterations must be at least 0")
        if any(c < 0 for c in self.exemplar_costs):
            raise ValueError("exemplar_costs must not be negative")
        if any(w < 0 for w in self.context_weights):
            raise ValueError("context_weights must not be negative")
        if not 0 <= self.guide_reseed < 1:
            raise ValueError("guide_reseed must be in [0, 1)")
        if not 0 <= self.final_reseed < 1:
            raise ValueError("final_reseed must be in [0, 1)")

    @property
    def has_context(self) -> bool:
        return any(w > 0 for w in self.context_weights)


@dataclass(frozen=True)
class EngineParams:
    """Parameters of the engine (front ends wrap them in their own configurations).

    The per-level fields (``patch_sizes``, ``max_iterations``, ``exemplar_costs``,
    ``context_weights``, ``guide_reseed``, ``final_reseed``) describe a uniform
    method: the same at every level. A front end that varies its method from level
    to level gives ``levels`` instead, one :class:`LevelPlan` per level, finest first
    (see :meth:`level_plans`).

    Parameters
    ----------
    patch_sizes : tuple of int
        Odd window width per pyramid level, finest first.
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
    max_iterations : int
        EM iterations per level at most (uniform plan).
    tolerance : float
        Stop a level when the target decreases by less than this fraction.
    patchmatch_passes : int
        PatchMatch passes per E-step (twice as many from a random start).
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
    exemplar_costs : tuple of float
        Uniform plan: the same exemplar costs at every level (see :class:`LevelPlan`).
    context_weights : tuple of float
        Uniform plan: context at every level but the coarsest (see :class:`LevelPlan`).
    guide_reseed : float
        Uniform plan: at every level the coarser one's matches are propagated to.
    final_reseed : float
        Uniform plan: after the finest level's EM.
    levels : tuple of LevelPlan
        The plan per level, finest first (empty: the uniform plan above). When
        given, the per-level fields above are not used.
    appearance_pyramid : {"laplacian", "gaussian"}
        What the appearance levels are: Laplacian bands (a level's colours are the
        sum of it and every coarser level) or Gaussian levels. Only the context uses it.
    vote : {"mean", "mode"}
        The M-step. ``"mean"`` (the paper): every pixel becomes the Gaussian-weighted
        mean of the estimates of the windows that cover it, the exact minimiser of
        the target for fixed matches, which blurs where the estimates disagree.
        ``"mode"``: every pixel copies the exemplar pixel that most of its windows
        (Gaussian-weighted) agree on, so the output is made of exemplar pixels and
        small features survive; a mode M-step that would raise the target is
        refused (the level then stops), so the target still never increases.
    quantize_features : bool
        Store the PCA window features as 16-bit integers in one unit per level
        (``_FEATURE_RANGE`` steps cover twice the largest value seen in the PCA
        samples) instead of float32: half the engine's largest arrays. The search
        proposes candidates on them; every accepted match is decided on the exact
        float window distance, so the target still never increases.
    """

    patch_sizes: tuple[int, ...] = (7, 11, 9)
    guide_weights: tuple[float, ...] = (1.0,)
    appearance_weights: tuple[float, ...] = (1.0,)
    position_weight: float = 0.0
    pca_fraction: float = 0.2
    pca_max_components: int | None = None
    pca_samples: int = 8000
    backend: str = "patchmatch"
    max_iterations: int = 8
    tolerance: float = 2e-3
    patchmatch_passes: int = 4
    normalize_bands: bool = True
    guide_padding: str = "constant"
    stride: int = 1
    init_from_guide: bool = True
    window_sigma: float = 1.0 / 3.0
    exemplar_costs: tuple[float, ...] = ()
    context_weights: tuple[float, ...] = ()
    guide_reseed: float = 0.0
    final_reseed: float = 0.0
    levels: tuple[LevelPlan, ...] = ()
    vote: str = "mean"
    quantize_features: bool = True
    appearance_pyramid: str = "laplacian"

    def __post_init__(self) -> None:
        if self.vote not in VOTES:
            raise ValueError(f"unknown vote {self.vote!r}; use one of {VOTES}")
        if any(k < 1 or k % 2 == 0 for k in self.patch_sizes):
            raise ValueError(f"patch sizes must be odd and positive, got {self.patch_sizes}")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; use one of {BACKENDS}")
        if not 0 < self.pca_fraction <= 1:
            raise ValueError("pca_fraction must be in (0, 1]")
        if self.guide_padding not in ("constant", "reflect", "edge"):
            raise ValueError("guide_padding must be 'constant', 'reflect' or 'edge'")
        if not 0 <= self.guide_reseed < 1:
            raise ValueError("guide_reseed must be in [0, 1)")
        if not 0 <= self.final_reseed < 1:
            raise ValueError("final_reseed must be in [0, 1)")
        if self.stride < 1 or self.max_iterations < 0:
            raise ValueError("stride must be at least 1 and max_iterations at least 0")
        if self.appearance_pyramid not in APPEARANCE_PYRAMIDS:
            raise ValueError("appearance_pyramid must be 'laplacian' or 'gaussian'")
        if any(not isinstance(plan, LevelPlan) for plan in self.levels):
            raise ValueError("levels must be LevelPlan objects, finest first")

    def level_plans(self, n_levels: int) -> tuple[LevelPlan, ...]:
        """The plan of each of ``n_levels`` levels, finest first.

        ``levels`` when given (it must have a plan per level), else the uniform plan
        of the per-level fields.
        """
        if self.levels:
            if len(self.levels) < n_levels:
                raise ValueError(f"{n_levels} levels need {n_levels} level plans")
            return tuple(self.levels[:n_levels])
        if len(self.patch_sizes) < n_levels:
            raise ValueError(
                f"{n_levels} levels need {n_levels} patch sizes, got {self.patch_sizes}"
            )
        return tuple(
            LevelPlan(
                patch_size=self.patch_sizes[level],
                max_iterations=self.max_iterations,
                exemplar_costs=self.exemplar_costs,
                context_weights=self.context_weights if level < n_levels - 1 else (),
                guide_reseed=self.guide_reseed,
                final_reseed=self.final_reseed if level == 0 else 0.0,
            )
            for level in range(n_levels)
        )
