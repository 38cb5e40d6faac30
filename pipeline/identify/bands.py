"""Uncertainty of the identified curves: bands from the block bootstrap's replicates, masks.

The parameters are re-estimated on ``B`` block resamples of the regression rows
(:func:`debist.identify.bootstrap.block_bootstrap`). Every curve is a linear map of the
parameters (:func:`curve_maps`), so each replicate gives a curve and the pointwise 2.5 and
97.5 percentiles a 95 % band. Two further half-widths are added in quadrature: the friction
bound ``|F_c| + sum_e k_e Delta_e`` of the static forces (:func:`friction_bound`) and a
model error calibrated on the virtual rig (:func:`model_error_table`).

A curve is *identified* at ``q`` where (1) the data support it: the Gaussian-weighted
number of estimation samples near ``q`` (the kernel of Eq. 38) is at least ``min_support``
on each side of ``q`` (for ``g_i`` only quasi-static samples where input ``i`` excites the
beam, for ``d`` only samples in motion), and (2) its band is at most ``band_tolerance``
times the curve's scale, the larger of its range and its largest magnitude.

Why, and how the model-error tables were calibrated: docs/explanation/calibration.md.

References
----------
Masoud & Maas 2025, Eq. 37-40; Efron & Tibshirani 1993, An Introduction to the Bootstrap,
Ch. 13 (percentile intervals); Wasserman 2006, All of
Nonparametric Statistics, Springer, Sec. 5.7 (bands cover the smoothed curve); JCGM
100:2008 Sec. 5.1.2 (root sum of squares); Kennedy & O'Hagan 2001, J. R. Stat. Soc. B
63(3), 425-464 (a model-discrepancy term calibrated against a known truth).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import lazy_loader as lazy
import numpy as np

from debist.core import metrics
from debist.identify.design import at_level
from debist.identify.excitation import input_active, quasi_static
from debist.identify.stability import small_signal
from debist.model.basis import RBFBasis
from debist.model.terms import PhysicsPrior, term_sign, term_table
from debist.model.termtable import input_map

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

#: Model-error half-width per curve, a fraction of its scale (of ``|g_i(q)|`` for the gains),
#: the wider of two calibrations: the virtual rig's seed-1 fleets and the plant zoo's seed 1,
#: whose every member's band holds the truth at >= 90 % of its marked points
#: (see docs/explanation/calibration.md).
MODEL_ERROR = {"restoring": 0.080, "d": 0.539, "g": 0.439, "F": 0.118}
#: Share of marked points whose :data:`MODEL_ERROR` band held the truth on independent fleets
#: and on the plant zoo (both seeds).
MEASURED_COVERAGE = "97-100 %"
#: The model error of a model with the analytical creep term (backbone ``physics_creep``).
MODEL_ERROR_CREEP = {"restoring": 0.02, "d": 0.451, "g": 0.317, "F": 0.125}
#: What the bands of :data:`MODEL_ERROR_CREEP` held on independent fleets (the lowest figure).
MEASURED_COVERAGE_CREEP = "98-100 %"
#: The model error without the effective-mass scale (``effective_mass = false``).
MODEL_ERROR_AS_FITTED = {"restoring": 0.088, "d": 0.652, "g": 0.576, "F": 0.205}
#: ... with ``physics_creep``.
MODEL_ERROR_CREEP_AS_FITTED = {"restoring": 0.086, "d": 0.451, "g": 0.553, "F": 0.185}
#: What the as-fitted tables' bands held on independent fleets.
MEASURED_COVERAGE_AS_FITTED = "98-100 %"
#: Model error of the tangent stiffness ``k* = dF/dq`` at a well, a fraction of ``|k*|``
#: (95th percentile over the wells of the calibration fleets).
STIFFNESS_ERROR = 0.207
#: The same without the effective-mass scale.
STIFFNESS_ERROR_AS_FITTED = 0.476
#: What the shared tables' bands held with the backbone term ``input_quadratic``.
MEASURED_COVERAGE_QUADRATIC = "81-100 %"
#: What the shared tables' bands held with the RBF term ``gh``.
MEASURED_COVERAGE_GH = "99-100 %"
#: What the shared tables' bands held with ``physics_quadratic``.
MEASURED_COVERAGE_PHYSICS_QUADRATIC = "97-100 %"
#: Measured coverage of a model with one of these terms (the shared tables were calibrated
#: without them): term name -> coverage.
MEASURED_COVERAGE_TERMS = {
    "input_quadratic": MEASURED_COVERAGE_QUADRATIC,
    "gh": MEASURED_COVERAGE_GH,
    "physics_quadratic": MEASURED_COVERAGE_PHYSICS_QUADRATIC,
}
#: (model-error table, measured coverage) per ``(physics_creep, effective_mass)``.
_CALIBRATION = {
    (False, True): (MODEL_ERROR, MEASURED_COVERAGE),
    (True, True): (MODEL_ERROR_CREEP, MEASURED_COVERAGE_CREEP),
    (False, False): (MODEL_ERROR_AS_FITTED, MEASURED_COVERAGE_AS_FITTED),
    (True, False): (MODEL_ERROR_CREEP_AS_FITTED, MEASURED_COVERAGE_AS_FITTED),
}
_D_NOTE = '; d(q*) and zeta say "not identified" where the damping curve is not'


def stiffness_label(model_error: bool = True, effective_mass: bool = True) -> str:
    """Say what the brackets of k* and f_n at the wells hold (beside the design table).

    Parameters
    ----------
    model_error : bool
        Whether the band carries the calibrated model error (``[identify] model_error``).
    effective_mass : bool
        Whether the model was fitted with the effective-mass scale (``effective_mass``).

    Returns
    -------
    str
    """
    error = stiffness_error(effective_mass)
    ran = "0.80-1.12 of" if effective_mass else "4-34 % below"
    if not model_error:
        return (
            "in brackets the bootstrap band of k* and f_n (nominal 95 %; on the virtual rig the "
            f"identified k* ran {ran} the truth, outside such a band)" + _D_NOTE
        )
    return (
        "in brackets the 95 % band of k* and f_n (bootstrap and a model error of "
        f"{100 * error:.0f} % of k*, calibrated on the virtual rig, where the identified "
        f"k* ran {ran} the truth)" + _D_NOTE
    )


def stiffness_error(effective_mass: bool = True) -> float:
    """Return k*'s calibrated model error as a fraction of |k*| [-].

    Parameters
    ----------
    effective_mass : bool
        Whether the model has the effective-mass scale (:mod:`debist.identify.mass`).

    Returns
    -------
    float
        :data:`STIFFNESS_ERROR`, or :data:`STIFFNESS_ERROR_AS_FITTED` without the scale.
    """
    return STIFFNESS_ERROR if effective_mass else STIFFNESS_ERROR_AS_FITTED


#: How the bands of k* and f_n at the wells are described beside the design table.
STIFFNESS_LABEL = stiffness_label(True)
#: The same without the model error (``[identify] model_error = false``).
STIFFNESS_BOOTSTRAP_LABEL = stiffness_label(False)
#: How a band is labelled wherever it is shown: what it is, and what it was measured to hold.
_BAND_TEMPLATE = (
    "95 % band (bootstrap and model error calibrated on the virtual rig; holds the truth at "
    "{coverage} there)"
)
BAND_LABEL = _BAND_TEMPLATE.format(coverage=MEASURED_COVERAGE)
#: The label of a bootstrap-only band (``[identify] model_error = false``), with its measured
#: coverage on the calibration fleets.
BOOTSTRAP_LABEL = (
    "bootstrap band (nominal 95 %; holds the truth at only 0-92 % on the virtual rig, "
    "depending on the curve)"
)


def model_error_table(backbone, effective_mass: bool = True) -> dict[str, float]:
    """Return the calibrated model error of a model with these backbone terms.

    Parameters
    ----------
    backbone : sequence of str
        The ``[identify] backbone`` terms.
    effective_mass : bool
        Whether the model has the effective-mass scale (``[identify] effective_mass``).

    Returns
    -------
    dict of str to float
        :data:`MODEL_ERROR_CREEP` with ``physics_creep``, else :data:`MODEL_ERROR`; their
        ``_AS_FITTED`` counterparts without the effective-mass scale.
    """
    return _CALIBRATION["physics_creep" in backbone, bool(effective_mass)][0]


def band_label(
    model_error: bool,
    creep: bool = False,
    effective_mass: bool = True,
    terms: Collection[str] = (),
) -> str:
    """Label of the curves' bands: :data:`BAND_LABEL`, or :data:`BOOTSTRAP_LABEL` without it.

    With ``creep`` (backbone ``physics_creep``) the label carries the coverage measured for
    :data:`MODEL_ERROR_CREEP`; without ``effective_mass`` that of the as-fitted tables; with
    a term of :data:`MEASURED_COVERAGE_TERMS` among ``terms`` (the model's RBF and backbone
    terms) the coverage measured for it, or the lowest of them with several (such pairs were
    not measured: the label gives the lower figure).
    """
    if not model_error:
        return BOOTSTRAP_LABEL
    coverage = _CALIBRATION[bool(creep), bool(effective_mass)][1]
    measured = [MEASURED_COVERAGE_TERMS[t] for t in terms if t in MEASURED_COVERAGE_TERMS]
    if measured:
        coverage = min(measured, key=lambda text: int(text.split("-")[0]))
    return _BAND_TEMPLATE.format(coverage=coverage)


def _model_error(table: dict[str, float] | None, name: str) -> float:
    """Model-error fraction of curve ``name`` (``g1``, ``g2`` read ``g``); 0 without a table."""
    if not table:
        return 0.0
    return float(table.get(name, table.get(name.rstrip("0123456789"), 0.0)))


#: Curves whose model error is a fraction of their local magnitude, not of their scale (gains).
RELATIVE_MODEL_ERROR = ("g",)


def relative_model_error(name: str) -> bool:
    """Return whether curve ``name``'s model error is a fraction of its local magnitude.

    Parameters
    ----------
    name : str
        Curve name (``restoring``, ``d``, ``g1``, ``g2`` ...; ``g1`` and ``g2`` read ``g``).

    Returns
    -------
    bool
        True for the gains of :data:`RELATIVE_MODEL_ERROR`.
    """
    return name.rstrip("0123456789") in RELATIVE_MODEL_ERROR


def error_level(name: str, value: np.ndarray, scale_points: np.ndarray, span: float) -> np.ndarray:
    """Return the magnitude a curve's model-error fraction multiplies, per grid point.

    Parameters
    ----------
    name : str
        Curve name (``restoring``, ``d``, ``g1`` ...).
    value : ndarray, shape (m,)
        The curve on the grid [unit of the curve].
    scale_points : ndarray of bool, shape (m,)
        The points the curve's scale is taken over.
    span : float
        The curve's scale there: the larger of its range and its largest magnitude.

    Returns
    -------
    ndarray, shape (m,)
        For a gain g_i (:data:`RELATIVE_MODEL_ERROR`) that keeps one sign over
        ``scale_points``, its local magnitude ``|g_i(q)|`` (a gain error scales the curve);
        else, and for every other curve, ``span`` at every point.

    References
    ----------
    Kennedy & O'Hagan 2001, J. R. Stat. Soc. B 63(3), 425-464 (the form of the discrepancy
    term is a modelling choice, calibrated against a known truth); JCGM 100:2008 (GUM)
    Sec. 5.1.6 (a relative standard uncertainty for a quantity whose error scales with it).
    """
    value = np.asarray(value, dtype=float)
    on = value[scale_points]
    one_signed = on.size > 0 and (bool(np.all(on > 0)) or bool(np.all(on < 0)))
    if relative_model_error(name) and one_signed:
        return np.abs(value)
    return np.full(value.shape, float(span))


#: Motion threshold for d: |q_dot| above this fraction of its RMS.
MOVING_FRACTION = 0.1
#: Names of the terms that are linear in the friction state z (the damping curve d).
_D_PREFIX, _D_SCALARS = "d[", ("viscous", "physics_damping")


def point_curves(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Evaluate the identified curves at positions ``q`` as the columns of the curve table.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    q : ndarray, shape (n,)
        Positions [unit of q].

    Returns
    -------
    dict of str to ndarray, each shape (n,)
        ``q``, ``c``, ``d``, ``cq`` (``c(q) q``), ``restoring`` (``c(q) q + F_0``, the
        static force at v = 0), then per input ``g<i>`` and ``dC<i>_dq`` (``2 g_i``).

    References
    ----------
    Masoud & Maas 2025, Eq. 37-39 and Fig. 14.
    """
    cur = model.curves(q)
    F_0 = float(model.backbone.get("F_0", 0.0))
    frame = {"q": q, "c": cur["c"], "d": cur["d"], "cq": cur["cq"]}
    frame["restoring"] = cur["cq"] + F_0
    for j in range(model.n_inputs):
        frame[f"g{j + 1}"] = cur["g"][:, j]
        frame[f"dC{j + 1}_dq"] = cur["dC_dq"][:, j]
    return frame


def curve_names(n_inputs: int) -> list[str]:
    """Names of the curves with bands: ``restoring``, ``d``, ``g1`` .. ``gN``."""
    return ["restoring", "d", *[f"g{j + 1}" for j in range(n_inputs)]]


def curve_maps(
    names: Sequence[str],
    q: np.ndarray,
    basis: RBFBasis,
    n_inputs: int,
    input_map_kind: str,
    coulomb_velocity: float,
    prior: PhysicsPrior | None = None,
    level: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Linear maps from the regression parameters to the characteristic curves.

    Built from the term library (:func:`debist.model.terms.term_table`): the restoring
    force is the force side at rest (``z = 0``, ``h(v) = 0``), the damping the terms linear
    in ``z`` at ``z = 1``, and ``g_j`` the gain terms of input ``j`` at ``h(v_j) = 1`` (those
    linear in ``h(v_j)``: a term in ``h(v_j)^2`` is not part of the small-signal gain). With
    ``level`` the static force at that held input level too, the force side at rest minus every
    input term.

    Parameters
    ----------
    names : sequence of str
        Regression column names (:attr:`FitDiagnostics.columns`); a ``"m_q"`` column
        (identified mass) maps to no curve.
    q : ndarray, shape (n,)
        Positions [unit of q].
    basis : RBFBasis
        The model's RBF basis.
    n_inputs : int
        Number of inputs.
    input_map_kind : {"v2", "v"}
        h(v).
    coulomb_velocity : float
        v_c [unit of q / s].
    prior : PhysicsPrior, optional
        The analytical curves of ``physics_*`` terms.
    level : ndarray, shape (n_inputs,), optional
        Mapped inputs h(v_i) of a held level [V^2 or V].

    Returns
    -------
    dict of str to ndarray, shape (n, len(names))
        ``restoring`` (curve = map @ theta: ``c(q) q + F_0`` [N]), ``d`` [N s/m] and
        ``g1`` .. ``gN`` [N/V^2 or N/V]; with ``level`` also ``F``, the static force at that
        level [N] (:meth:`debist.model.rbf.RBFModel.static_force`).

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40.
    """
    q = np.asarray(q, dtype=float)
    names = list(names)
    terms = [n for n in names if n != "m_q"]
    idx = np.array([names.index(n) for n in terms], dtype=int)
    table = term_table(terms, basis, n_inputs, input_map_kind, coulomb_velocity, prior)
    n = q.size
    zero_h = np.zeros((n, n_inputs))

    def full(cols: np.ndarray, keep: np.ndarray) -> np.ndarray:
        out = np.zeros((n, len(names)))
        out[:, idx[keep]] = cols[:, keep]
        return out

    rest = table.columns(q, np.zeros(n), zero_h)
    maps = {"restoring": full(rest, np.ones(len(terms), dtype=bool))}
    is_d = np.array([t.startswith(_D_PREFIX) or t in _D_SCALARS for t in terms], dtype=bool)
    maps["d"] = full(table.columns(q, np.ones(n), zero_h), is_d)
    for j in range(n_inputs):
        h = zero_h.copy()
        h[:, j] = 1.0
        own = (f"g{j + 1}[", f"input_gain{j + 1}", f"physics_gain{j + 1}")
        is_g = np.array([t.startswith(own) for t in terms], dtype=bool)
        maps[f"g{j + 1}"] = full(table.columns(q, np.zeros(n), h), is_g)
    if level is not None:
        sign = -np.array([term_sign(t) for t in terms])  # force side minus the input terms
        held = np.broadcast_to(np.asarray(level, dtype=float), (n, n_inputs))
        maps["F"] = full(table.columns(q, np.zeros(n), held) * sign, np.ones(len(terms), bool))
    return maps


def support_weights(
    grid: np.ndarray,
    q: np.ndarray,
    sigma: float,
    mask: np.ndarray | None = None,
    reach: float = np.inf,
    two_sided: bool = False,
) -> np.ndarray:
    """Gaussian-weighted number of samples near each grid point (Eq. 38 kernel).

    Parameters
    ----------
    grid : ndarray, shape (m,)
        Positions [unit of q].
    q : ndarray, shape (n,)
        Sample positions [unit of q].
    sigma : float
        Kernel width [unit of q].
    mask : ndarray of bool, shape (n,), optional
        Samples that count.
    reach : float, optional
        Samples farther than this from a grid point do not count there [unit of q]; default
        all count. With ``reach = sigma`` a point is supported only by samples within the
        reach of one RBF (:meth:`RBFBasis.support`): thousands of samples in a well then
        cannot lend their Gaussian tails to an interval the data never visited.
    two_sided : bool, optional
        Count the samples on each side of a grid point apart (below and above it; a bin
        holding the point is split in proportion) and return twice the smaller count: a
        point at or beyond the edge of the data, where a curve is extrapolated from one
        side, gets little or no support however many samples lie on the other side, while a
        point inside the data keeps about its plain count (half the samples on each side).
        Default False.

    Returns
    -------
    ndarray, shape (m,)
        ``sum_s exp(-(grid - q_s)^2 / (2 sigma^2))`` over the counted samples within
        ``reach`` (two-sided: ``2 min(W_below, W_above)`` of the two halves of that sum),
        with the samples binned at about sigma / 8 (memory independent of the record length;
        a bin counts when its centre is within ``reach``).

    References
    ----------
    Masoud & Maas 2025, Eq. 38 (the kernel); Fan & Gijbels 1996, Local Polynomial Modelling
    and Its Applications, Chapman & Hall, Sec. 3.2.5 (a kernel estimate at a boundary point
    of the data is biased: it sees the data from one side).
    """
    qs = np.asarray(q, dtype=float)
    if mask is not None:
        qs = qs[mask]
    counts, edges = np.histogram(qs, bins=max(16, int(np.ptp(grid) / sigma * 8) + 1))
    mids = 0.5 * (edges[:-1] + edges[1:])
    if qs.size == 0:
        return np.zeros(np.size(grid))
    signed = mids[None, :] - np.asarray(grid, dtype=float)[:, None]
    dist = np.abs(signed)
    weights = np.where(dist <= reach, np.exp(-(dist**2) / (2 * sigma**2)), 0.0)
    if not two_sided:
        return weights @ counts
    # the share of each bin below the point (its samples taken as uniform within the bin)
    share = np.clip(0.5 - signed / (edges[1] - edges[0]), 0.0, 1.0)
    below = (weights * share) @ counts
    above = (weights * (1.0 - share)) @ counts
    return 2.0 * np.minimum(below, above)


def curve_bands(
    point: dict[str, np.ndarray],
    maps: dict[str, np.ndarray],
    theta: np.ndarray,
    theta_boot: np.ndarray | None,
    support: dict[str, np.ndarray],
    min_support: float,
    band_tolerance: float,
    systematic: dict[str, float] | None = None,
    model_error: dict[str, float] | None = None,
    reach: dict[str, np.ndarray] | None = None,
) -> pd.DataFrame:
    """Bands and identified masks of the curves on a grid.

    Parameters
    ----------
    point : dict of str to ndarray, shape (m,)
        The identified curves (``restoring``, ``d``, ``g1`` ...).
    maps : dict of str to ndarray, shape (m, p)
        :func:`curve_maps` on the same grid.
    theta : ndarray, shape (p,)
        The least-squares parameters.
    theta_boot : ndarray, shape (B, p) or None
        Bootstrap replicates; None: no band (every point unidentified).
    support : dict of str to ndarray, shape (m,)
        :func:`support_weights` per curve; supported where at least ``min_support``.
    min_support : float
        Smallest supported weight.
    band_tolerance : float
        Largest band width relative to the curve's scale over ``reach`` (the larger of its
        range and its largest magnitude there).
    systematic : dict of str to float, optional
        Per curve a bound of its systematic error [unit of the curve] (:func:`friction_bound`).
    model_error : dict of str to float, optional
        Per curve (``g`` for every ``g_i``) a model-error fraction (:func:`error_level`,
        :data:`MODEL_ERROR`); default none (a bootstrap-only band).
    reach : dict of str to ndarray, shape (m,), optional
        Per curve the weights whose supported points the scale is taken over; default
        ``support``.

    Returns
    -------
    pandas.DataFrame
        Per curve ``<name>_lo``, ``<name>_hi`` (95 % band) and ``<name>_identified``.

    References
    ----------
    Efron & Tibshirani 1993, Ch. 13 (percentile intervals); JCGM 100:2008 (GUM) Sec. 5.1.2
    (root sum of squares of uncorrelated contributions).
    """
    systematic = systematic or {}
    cols: dict[str, np.ndarray] = {}
    for name, value in point.items():
        ok = support[name] >= min_support
        near = (reach or support)[name] >= min_support
        if theta_boot is None:
            lo = hi = np.full(value.shape, np.nan)
            ident = np.zeros(value.shape, dtype=bool)
        else:
            # the curve's scale: its range or, for a one-signed flat curve such as a gain
            # g_i (range near 0, magnitude not), its largest magnitude where supported
            span = np.ptp(value[near]) if near.any() else 0.0
            span = max(span, float(np.max(np.abs(value[near]), initial=0.0)))
            dev = (theta_boot - theta) @ maps[name].T  # (B, m): replicate minus estimate
            level = error_level(name, value, near, span)
            bound = np.hypot(systematic.get(name, 0.0), _model_error(model_error, name) * level)
            lo = value - _widen(-np.percentile(dev, 2.5, axis=0), bound)
            hi = value + _widen(np.percentile(dev, 97.5, axis=0), bound)
            ident = ok & (hi - lo <= band_tolerance * span) & (span > 0)
        cols[f"{name}_lo"], cols[f"{name}_hi"], cols[f"{name}_identified"] = lo, hi, ident
    return pd.DataFrame(cols)


def _widen(reach: np.ndarray, bound: float | np.ndarray) -> np.ndarray:
    """Widen a band edge's outward reach by a systematic bound (per point or one), in quadrature.

    ``reach`` is the edge's distance outward from the estimate (negative where the
    percentile band does not hold the estimate); without a bound it is returned as is.
    """
    return np.where(reach >= 0.0, np.hypot(reach, bound), reach + bound)


def friction_bound(model) -> float:
    """Bound of the error of a static force identified where the beam rests.

    The Coulomb level ``|F_c|`` plus the Maxwell-slip elements' slip forces
    ``sum_e k_e Delta_e``: both frictions act in parallel and together hold the beam at rest
    against any static force up to their sum.

    Parameters
    ----------
    model : RBFModel
        The identified model; its backbone's Coulomb level ``F_c`` [N] (0 without the
        ``coulomb`` term) and its slip elements (none without ``[identify] slip``).

    Returns
    -------
    float
        ``|F_c| + sum_e k_e Delta_e`` [N, or N/kg for ``m_q = 1``]: the rest positions pin a
        static force down only to +- this bound (see the module docstring).

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (the friction term of the backbone); Olsson et al. 1998,
    Eur. J. Control 4(3), 176-195 (stiction: rest under any force below the breakaway);
    Al-Bender, Lampaert & Swevers 2005 (the elements' slip forces).
    """
    slip = model.slip_elements()["F_total"] if getattr(model, "has_slip", False) else 0.0
    return abs(float(model.backbone.get("F_c", 0.0))) + abs(float(slip))


def identified_intervals(q: np.ndarray, mask: np.ndarray) -> list[list[float]]:
    """Contiguous runs of a mask on a grid as ``[q_start, q_end]`` intervals [unit of q]."""
    mask = np.asarray(mask, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [
        [float(f"{q[s]:.6g}"), float(f"{q[e - 1]:.6g}")]
        for s, e in zip(edges[::2], edges[1::2], strict=True)
    ]


#: The curves that are the beam's physics (Eq. 37): the damping and the DE force gains.
PHYSICAL_CURVES = ("d", "g")


def simulation_only(identified: dict[str, list], fitted: Collection[str] | None = None) -> str:
    """Word which physical curves of a model are identified nowhere, or ``""``.

    A model whose damping ``d(q)`` or DE gains ``g_i(q)`` are identified nowhere (their bands
    too wide or no data support, :func:`curves_frame`) may still free-run well, but those
    curves are not the beam's: it is a simulator only.

    Parameters
    ----------
    identified : dict of str to list of [float, float]
        Curve name (``restoring``, ``d``, ``g1``, ...) to the intervals of q where it is
        identified, as the identify summary's ``identified``.
    fitted : collection of str, optional
        The curves the model fits as RBF sums (:func:`fitted_curves`); the others are a
        backbone constant or a given gain (a model with ``rbf = []``, as IDIM), not curves,
        and are left out. Default: every curve in ``identified``.

    Returns
    -------
    str
        E.g. ``"d, g1, g2 identified nowhere (restoring holds on part of q)"``; ``""`` when
        every physical curve is identified somewhere.

    References
    ----------
    Masoud & Maas 2025, Eq. 37 (the curves ``c``, ``d``, ``g_i``).

    Examples
    --------
    >>> simulation_only({"restoring": [[-1.0, 1.0]], "d": [], "g1": [], "g2": []})
    'd, g1, g2 identified nowhere (restoring holds on part of q)'
    >>> simulation_only({"restoring": [], "d": [], "g1": [[0.0, 2.0]]})
    'd identified nowhere (g1 holds on part of q; restoring nowhere)'
    >>> simulation_only({"d": [[0.0, 1.0]], "g1": [[0.0, 1.0]]})
    ''
    >>> simulation_only({"restoring": [], "d": [], "g1": []}, fitted=())
    ''
    """
    if fitted is not None:
        identified = {n: spans for n, spans in identified.items() if n in fitted}

    def physical(name: str) -> bool:
        return name.rstrip("0123456789") in PHYSICAL_CURVES

    nowhere = [n for n, spans in identified.items() if physical(n) and not spans]
    if not nowhere:
        return ""
    held = [n for n, spans in identified.items() if spans]
    others = [n for n, spans in identified.items() if not physical(n) and not spans]
    parts = [f"{', '.join(held)} {'holds' if len(held) == 1 else 'hold'} on part of q"] * bool(held)
    parts += [f"{', '.join(others)} nowhere"] * bool(others)
    return f"{', '.join(nowhere)} identified nowhere" + (f" ({'; '.join(parts)})" if parts else "")


def fitted_curves(model) -> set[str]:
    """Name the curves a model fits as RBF sums: ``restoring``, ``d``, ``g1``, ... .

    Parameters
    ----------
    model : RBFModel
        The identified model (its weights ``theta_c``, ``theta_d``, ``theta_g``; zeros where
        a curve is not in ``[identify] rbf``).

    Returns
    -------
    set of str
        ``restoring`` with ``c(q)`` weights, ``d`` with ``d(q)`` weights, ``g<i>`` with weights
        of ``g_i(q)``.

    References
    ----------
    Masoud & Maas 2025, Eq. 38-39 (the RBF sums of the curves).
    """
    names = {"restoring"} if np.any(model.theta_c) else set()
    names |= {"d"} if np.any(model.theta_d) else set()
    theta_g = np.atleast_2d(np.asarray(model.theta_g, dtype=float))
    return names | {f"g{i + 1}" for i, row in enumerate(theta_g) if np.any(row)}


def curves_frame(
    model,
    diag,
    records,
    *,
    min_support: float,
    band_tolerance: float,
    model_error: dict[str, float] | None = None,
    n=201,
):
    """Tabulate the identified curves on a grid with their bands and identified masks.

    Parameters
    ----------
    model : RBFModel
        The identified model (after refinement, the refined one: its curves are the
        points, the least-squares bootstrap deviations give the band around them).
    diag : FitDiagnostics
        The least-squares diagnostics (``columns``, ``theta``, ``theta_boot``).
    records : sequence of Record
        The estimation records (``q``, ``q_dot``, ``v``), for the data support.
    min_support : float
        Smallest Gaussian-weighted sample count for a supported point.
    band_tolerance : float
        Largest band width relative to the curve's range.
    model_error : dict of str to float, optional
        Model-error fractions of :func:`curve_bands` (:data:`MODEL_ERROR`); none: bootstrap
        bands.
    n : int
        Grid points over the model's ``q_range``.

    Returns
    -------
    curves : pandas.DataFrame
        ``q, c, d, cq, restoring`` (= ``c(q) q + F_0`` [N], the static force at v = 0),
        ``g1..gN``, ``dC1_dq..dCN_dq`` and per curve of :func:`curve_names`
        ``<name>_lo``, ``<name>_hi``, ``<name>_identified``.
    intervals : dict of str to list
        Per curve the q intervals ``[a, b]`` where it is identified [unit of q].

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40 (curves), Fig. 14.
    """
    grid = np.linspace(model.q_range[0], model.q_range[1], n)
    frame = point_curves(model, grid)
    point = {name: frame[name] for name in curve_names(model.n_inputs)}
    maps = curve_maps(
        diag.columns,
        grid,
        model.basis,
        model.n_inputs,
        model.input_map,
        model.coulomb_velocity,
        model.prior,
    )
    q = np.concatenate([r.q for r in records])
    q_dot = np.concatenate([r.q_dot for r in records])
    active = input_active(np.vstack([r.v for r in records]))
    rms = metrics.rms(q_dot)
    sigma = model.basis.sigma
    # Each curve counts the samples that inform it, within one RBF width (a point's value
    # is a blend of the centres within about sigma): the restoring force where the beam
    # rests or moves slowly (below; a transit alone does not separate it from d(q) z), d
    # where it moves.
    slow = np.concatenate([quasi_static(r.q_dot) for r in records])
    counted = {"restoring": slow, "d": np.abs(q_dot) > MOVING_FRACTION * rms}
    # g_i counts the samples where v_i excites the beam (sub-threshold levels included: they
    # inform g_i wherever g_i h(v_i) stands above the regression's noise) while the beam is
    # quasi-static: along a switching transit q_dot is a function of q, so c(q) q, d(q) z and
    # g_i(q) h(v_i) enter Eq. 40 as one function of q there and the transit alone does not
    # separate g_i.
    for j in range(model.n_inputs):
        counted[f"g{j + 1}"] = active[:, j] & slow
    # A point is supported where those samples surround it (two-sided: not at or beyond the
    # edge of the data, where the curve is extrapolated from one side). The scale of the
    # restoring force and d is taken over every point the samples reach (one-sided): the
    # range of a force that crosses zero at a well grows over the well's flanks. A gain g_i is
    # one-signed and its scale is its magnitude, which only the supported points certify: one
    # RBF width past the data's edge the extrapolated gain can be several times the truth
    # (the full plant's calibration fleet: 3x), and a band judged against that magnitude
    # would be marked while wider than the true curve's range.
    support = {
        name: support_weights(grid, q, sigma, m, sigma, two_sided=True)
        for name, m in counted.items()
    }
    reach = {
        name: support[name] if name.startswith("g") else support_weights(grid, q, sigma, m, sigma)
        for name, m in counted.items()
    }
    bands = curve_bands(
        point, maps, diag.theta, diag.theta_boot, support, min_support, band_tolerance,
        {"restoring": friction_bound(model)}, model_error, reach,
    )  # fmt: skip
    out = pd.concat([pd.DataFrame(frame), bands], axis=1)
    intervals = {
        name: identified_intervals(grid, out[f"{name}_identified"].to_numpy()) for name in point
    }
    return out, intervals


def static_frame(
    model,
    diag,
    records,
    levels: Sequence[Sequence[float]],
    *,
    min_support: float,
    band_tolerance: float,
    model_error: dict[str, float] | None = None,
    n: int = 201,
) -> tuple[pd.DataFrame, list[dict]]:
    """Tabulate the static force of the identified model at held levels, with bands, masks.

    At a constant input ``v`` an external force
    ``F(q; v) = c(q) q + F_0 - sum_i g_i(q) h(v_i)`` holds the beam at ``q`` (Eq. 37 at rest;
    the identified counterpart of Fig. 4). ``F`` gets the bootstrap band of :func:`curve_bands`
    and is identified at ``q`` where the data dwelt near ``q`` at that level (two sides counted
    together, :func:`debist.identify.design.at_level`) and the band is narrow.

    Parameters
    ----------
    model : RBFModel
        The identified model.
    diag : FitDiagnostics
        The least-squares diagnostics (``columns``, ``theta``, ``theta_boot``).
    records : sequence of Record
        The estimation records (``q`` [m], ``v`` [V]).
    levels : sequence of sequence of float
        Input vectors [V] (:func:`debist.identify.design.held_levels`).
    min_support, band_tolerance, model_error
        As :func:`curves_frame` (the static force reads ``model_error["F"]``).
    n : int
        Grid points over the model's ``q_range``.

    Returns
    -------
    frame : pandas.DataFrame
        One row per level and grid point: ``level``, ``v1..vN`` [V], ``q`` [m], ``F``,
        ``F_lo``, ``F_hi`` [N, or N/kg for ``m_q = 1``] and ``F_identified``.
    intervals : list of dict
        Per level ``{"v": [...], "identified": [[q_a, q_b], ...]}``.

    References
    ----------
    Masoud & Maas 2025, Eq. 37, Fig. 4.
    """
    grid = np.linspace(model.q_range[0], model.q_range[1], n)
    q = np.concatenate([r.q for r in records])
    bound = {"F": friction_bound(model)}
    frames, intervals = [], []
    for k, level in enumerate(levels):
        h = input_map(np.asarray(level, dtype=float), model.input_map)
        point = model.static_force(grid, level)
        linear = curve_maps(
            diag.columns, grid, model.basis, model.n_inputs, model.input_map,
            model.coulomb_velocity, model.prior, level=h,
        )["F"]  # fmt: skip
        # one-sided: at a held level the beam rests at one position, a cluster of samples
        # narrower than the RBF width, and F is marked within that width of it
        support = support_weights(grid, q, model.basis.sigma, at_level(records, level))
        band = curve_bands(
            {"F": point}, {"F": linear}, diag.theta, diag.theta_boot, {"F": support},
            min_support, band_tolerance, bound, model_error,
        )  # fmt: skip
        frame = {"level": np.full(n, k)}
        frame.update({f"v{j + 1}": np.full(n, float(level[j])) for j in range(h.size)})
        frames.append(pd.concat([pd.DataFrame({**frame, "q": grid, "F": point}), band], axis=1))
        mask = band["F_identified"].to_numpy()
        intervals.append({"v": [float(x) for x in level],
                          "identified": identified_intervals(grid, mask)})  # fmt: skip
    if not frames:
        columns = ["level", *[f"v{j + 1}" for j in range(model.n_inputs)], "q", "F", "F_lo",
                   "F_hi", "F_identified"]  # fmt: skip
        return pd.DataFrame({c: [] for c in columns}), intervals
    return pd.concat(frames, ignore_index=True), intervals


def stiffness_bands(
    equilibria, model, diag, model_error: bool = True, effective_mass: bool = True
) -> pd.DataFrame:
    """Bands of the tangent stiffness ``k*`` and the natural frequency ``f_n`` at the wells.

    ``k* = dF/dq`` at an equilibrium is a linear map of the parameters like every curve (the
    derivative of the static force's map of :func:`curve_maps` at the level's input, by a
    central difference of a thousandth of the RBF width), so it gets the bootstrap band of
    :func:`curve_bands`, widened in quadrature by the calibrated model error
    :data:`STIFFNESS_ERROR` ``|k*|`` (the identified curves' slopes at the wells are biased low
    on the virtual rig, their values are not). ``f_n = sqrt(k*/m_q)/(2 pi)`` takes the band's
    ends (0 where the lower end is not positive).

    Parameters
    ----------
    equilibria : pandas.DataFrame
        :func:`debist.identify.design.design_numbers` rows (``model``, ``level``,
        ``v1..vN`` [V], ``q``, ``static_stable``, ``k`` [N/m], ``m_q`` [kg]).
    model : RBFModel
        The identified model.
    diag : FitDiagnostics
        Its least-squares diagnostics (``columns``, ``theta``, ``theta_boot``).
    model_error : bool
        Add the calibrated model error (``[identify] model_error``); else the bootstrap band
        alone.
    effective_mass : bool
        Whether the model has the effective-mass scale: :data:`STIFFNESS_ERROR`, else
        :data:`STIFFNESS_ERROR_AS_FITTED`.

    Returns
    -------
    pandas.DataFrame
        ``equilibria`` with ``k_lo``, ``k_hi`` [N/m] and ``f_n_lo``, ``f_n_hi`` [Hz] (95 %), set
        at the identified model's wells (NaN elsewhere, and without bootstrap replicates); its
        ``attrs`` kept.

    References
    ----------
    Efron & Tibshirani 1993, Ch. 13 (percentile intervals); JCGM 100:2008 (GUM) Sec. 5.1.2;
    Kennedy & O'Hagan 2001 (a calibrated model-discrepancy term).
    """
    out = equilibria.copy()
    out.attrs = dict(equilibria.attrs)
    bands = {c: np.full(len(out), np.nan) for c in ("k_lo", "k_hi", "f_n_lo", "f_n_hi")}
    inputs = [f"v{j + 1}" for j in range(model.n_inputs)]
    wells = (out["model"] == "rbf").to_numpy() & out["static_stable"].fillna(False).to_numpy(bool)
    step = 1e-3 * model.basis.sigma
    for i in np.flatnonzero(wells) if diag.theta_boot is not None else ():
        row = out.iloc[i]
        q = float(row["q"])
        h = input_map(row[inputs].to_numpy(float), model.input_map)
        force = curve_maps(
            diag.columns, np.array([q - step, q + step]), model.basis, model.n_inputs,
            model.input_map, model.coulomb_velocity, model.prior, level=h,
        )["F"]  # fmt: skip
        k_map = (force[1] - force[0]) / (2.0 * step)
        dev = (diag.theta_boot - diag.theta) @ k_map
        k = float(row["k"])
        bound = stiffness_error(effective_mass) * abs(k) if model_error else 0.0
        lo = k - float(_widen(-np.percentile(dev, 2.5), bound))
        hi = k + float(_widen(np.percentile(dev, 97.5), bound))
        bands["k_lo"][i], bands["k_hi"][i] = lo, hi
        # f_n of each end as the stability table computes it; 0 where the end is not positive
        bands["f_n_lo"][i], bands["f_n_hi"][i] = (
            np.nan_to_num(small_signal(x, float(row["m_q"]), 0.0)[0]) for x in (lo, hi)
        )
    for name, values in bands.items():
        out[name] = values
    return out
