"""Section 3 of Masoud & Maas 2025: the physics-based model of the bistable DE actuator.

Modules
-------
params
    :class:`~debist.physics.params.PrototypeParams`, Table 1 and the geometry in SI units.
kinematics
    Ritz approximation (Eq. 13), tip displacement, pitch angle, DE lengths (Eq. 1-6).
energy
    Potential energy (Eq. 9-11) with exact gradient and Hessian; capacitances.
statics
    Equilibria (Eq. 15), F(q) by continuation (Fig. 4), C(q) and dC/dq (Fig. 5).
prestrain
    Equilibria versus pre-strain, z_b,min and z_b,max (Fig. 3).
dynamics
    Full state-space model (Eq. 19-23), simulation, SVD mode analysis (Fig. 6a).
reduced
    Reduced one-coordinate model (Eq. 24-26), its curves, full vs reduced (Fig. 7).
analysis
    The design analysis of Section 3 in one call (Fig. 3-7); its figures are drawn by
    :mod:`debist.report.physics_plots`.

The interpretations of the printed equations follow ``docs/interpretation.md`` and are
documented where they are used.
"""
