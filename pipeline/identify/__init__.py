"""Section 4 of Masoud & Maas 2025: the identification of the physics-informed RBF model.

Estimation only (the model itself is :mod:`debist.model`): :mod:`.config` (the
``[identify]`` table), :mod:`.fit` (least squares with diagnostics and the T_z search,
:func:`~debist.identify.fit.fit_rbf_model`), :mod:`.regularise` (smoothing and sign
constraints), :mod:`.bands`, :mod:`.excitation`, :mod:`.stability`, :mod:`.design`,
:mod:`.autotune` (blocked cross-validation), :mod:`.refine` (the simulation-error
refinement), :mod:`.records` (the records of Eq. 40 from the stages' tables) and
:mod:`.physics_prior` (the analytical model's backbone, m_q and phi(q) as priors). This
package's ``__init__`` imports none of them, so that checking a workflow's
``[identify]`` table does not load the estimation code.
"""
