"""Section 4 of Masoud & Maas 2025: the identification of the physics-informed RBF model.

Estimation only (the model itself is :mod:`debist.model`): :mod:`.config` (the
``[identify]`` table), :mod:`.fit` (least squares with diagnostics and the T_z search,
:func:`~debist.identify.fit.fit_rbf_model`), :mod:`.regularise` (smoothing and sign
constraints), :mod:`.bands`, :mod:`.excitation`, :mod:`.stability`, :mod:`.design`,
:mod:`.autotune` (blocked cross-validation) and :mod:`.refine` (the simulation-error
refinement). This package's ``__init__`` imports none of them, so that checking a workflow's
``[identify]`` table does not load the estimation code.
"""
