"""Where a fitted model fails and which effect is missing.

``projections`` (projections orthogonal to a fit and score tests), ``residual_structure``
(harmonics of θ0 and covariate trends left in the residual), ``physical_aliases`` (exact
physical aliases in words and numbers: gravity ≡ field offset …), ``candidates`` (each effect
tested as the missing one, free and at physics), ``what_if`` (variants of a table: more angles,
half the amplitude …), ``indistinguishable`` (effects the table cannot tell apart, and the
measurement that would), ``discovery`` (beyond the catalog: the terms of the rows' covariates
the residual follows, by sparse regression with stability selection, each with its physical
plugin) and ``verdict`` (:func:`diagnose`: structure, candidates, groups and the verdict).

May import: ``mows.lab.model``, ``mows.lab.data``, ``mows.lab.progress`` and the core below the lab.
"""
