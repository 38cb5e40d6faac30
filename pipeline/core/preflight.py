"""Resource preflight: estimate a stage's largest arrays before it allocates them.

Every function that builds arrays whose size a workflow key controls calls one of the
checks below first, so that a setting such as ``[identify] M = 100000`` is refused in
microseconds with a :class:`~debist.core.errors.ResourceError` (a ``WorkflowError``, exit
code 2) that names the key and the estimate, instead of ending in the kernel's
out-of-memory killer. The estimates count the float64 arrays the code builds, copy by
copy (see each function's Notes), and take the largest of a stage's phases.

The memory budget is :data:`RAM_FRACTION` of the memory this process may use (the
smaller of the physical RAM reported by psutil and a Linux cgroup limit), or
``DEBIST_MEMORY_BUDGET_GB`` gigabytes (10^9 bytes) when that environment variable is set.

Measured accuracy (peak resident set size of a fresh process minus its size before the
call, ``resource.getrusage``; numpy 2.4, OpenBLAS): :func:`identify_bytes` against
``fit_rbf_model`` on 100000 x 153 (T_z fixed: 620 MB measured, 613 MB estimated; T_z
search: 645 MB; with ``lowpass``: 656 MB), 200000 x 203 (1637 MB measured, 1634 MB
estimated) and 3000 x 6003 (1158 MB measured, 1224 MB estimated): within 7 %.
:mod:`tracemalloc` sees only the arrays numpy allocates through Python's allocator, not
LAPACK's copies and work space (numpy's linalg allocates those with ``malloc``), so it
reports about two thirds of the estimate (tests/core/test_preflight.py).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil

from debist.core.errors import ResourceError, WorkflowError

__all__ = [
    "BAND_GRID",
    "BUDGET_ENV",
    "CURVE_GRID",
    "DEFLATE_MAX_RATIO",
    "RAM_FRACTION",
    "RESAMPLE_COPIES",
    "TEXT_PARSE_RATIO",
    "check_identify",
    "check_identify_config",
    "check_memory",
    "format_bytes",
    "free_run_bytes",
    "identify_bytes",
    "identify_columns",
    "identify_lower_bound",
    "identify_setting",
    "memory_budget",
    "narx_bytes",
    "refine_bytes",
    "sindy_bytes",
    "sindy_terms",
]

#: Environment variable that sets the memory budget [GB = 10^9 bytes].
BUDGET_ENV = "DEBIST_MEMORY_BUDGET_GB"
#: Fraction of the available memory used as the default budget.
RAM_FRACTION = 0.5
#: Largest expansion of the deflate format: one stored byte decodes to at most about
#: 1032 bytes (RFC 1951; a 258-byte match coded in 2 bits). Used for compressed data sets.
DEFLATE_MAX_RATIO = 1032
#: Most memory pandas' C parser needs per byte of a text log [bytes/byte]: peak RSS
#: minus the start, for 30 MB of one-character fields (``0\n``, ``0,0,0,0\n``) 7.2-7.4,
#: for 20 MB 10.5 (pandas 3.1, numpy 2.3); fields of 3-4 characters need 3. Bounds the
#: decompressed size of a gzip'd log (:mod:`debist.ingest.compressed`).
TEXT_PARSE_RATIO = 12
#: Positions at which the identify stage evaluates the identified curves (the stability
#: analysis's grid, :func:`debist.identify.stability.equilibria`).
CURVE_GRID = 4001
#: Positions of the curves' bootstrap bands; each replicate's deviation from the estimate
#: there and the percentiles' sorted copy are held per curve
#: (:func:`debist.identify.bands.curves_frame`, :func:`debist.identify.bands.curve_bands`).
BAND_GRID = 201
#: float64 copies of a resampled segment alive at once, per sample and channel (the
#: time grid, the resampled block, the copy that keeps the samples within the record, and
#: the column stack of the rasters' overlap).
RESAMPLE_COPIES = 4
#: Bytes of one float64.
_F8 = 8
_GB = 1e9
#: Linux cgroup files holding a memory limit (v2, then v1).
_CGROUP_LIMITS = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes")

#: Backbone terms that add one force column each, and those among them multiplied by z.
_FORCE_SCALARS = (
    "linear_spring",
    "cubic_spring",
    "viscous",
    "coulomb",
    "offset",
    "physics_spring",
    "physics_damping",
)
_Z_TERMS = ("viscous", "coulomb", "physics_damping")
#: Backbone terms that add one input column per input.
_INPUT_VECTORS = ("input_gain", "input_quadratic", "physics_gain", "physics_quadratic")


def format_bytes(nbytes: float) -> str:
    """Format a byte count with a decimal unit.

    Parameters
    ----------
    nbytes : float
        A size [bytes].

    Returns
    -------
    str
        Three significant digits and kB, MB, GB, TB or PB (powers of 1000).

    Examples
    --------
    >>> format_bytes(27.4e9), format_bytes(512), format_bytes(3.2e16)
    ('27.4 GB', '0.512 kB', '32 PB')
    """
    for unit, size in (("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if nbytes >= size:
            return f"{nbytes / size:.3g} {unit}"
    return f"{nbytes / 1e3:.3g} kB"


def _cgroup_limit() -> int | None:
    for name in _CGROUP_LIMITS:
        try:
            text = Path(name).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            return int(text)
    return None


def _budget() -> tuple[int, str]:
    """Return the budget [bytes] and where it comes from (for messages)."""
    raw = os.environ.get(BUDGET_ENV, "").strip()
    if raw:
        try:
            gb = float(raw)
        except ValueError:
            gb = math.nan
        if not (math.isfinite(gb) and gb > 0):
            raise WorkflowError(f"{BUDGET_ENV} = {raw!r} must be a number of gigabytes > 0")
        return int(gb * _GB), f"set by {BUDGET_ENV}"
    total = psutil.virtual_memory().total
    limit = _cgroup_limit()
    where = "this machine's RAM"
    if limit is not None and limit < total:
        total, where = limit, "this container's memory limit"
    share = "half" if RAM_FRACTION == 0.5 else f"{RAM_FRACTION:g}"
    return int(RAM_FRACTION * total), f"{share} of {where}; set {BUDGET_ENV} to change it"


def memory_budget() -> int:
    """Return the memory budget a single stage may allocate.

    Returns
    -------
    int
        ``DEBIST_MEMORY_BUDGET_GB`` x 10^9 when the variable is set, else
        :data:`RAM_FRACTION` of the physical RAM (psutil) or of a smaller cgroup limit
        [bytes].

    Raises
    ------
    WorkflowError
        If ``DEBIST_MEMORY_BUDGET_GB`` is set but not a positive number.

    References
    ----------
    psutil, ``virtual_memory().total``; Linux cgroup v2 ``memory.max``.
    """
    return _budget()[0]


def check_memory(nbytes: float, setting: str, need: str, detail: str = "") -> None:
    """Refuse an estimate above the memory budget.

    Parameters
    ----------
    nbytes : float
        Estimated peak [bytes].
    setting : str
        The workflow key and its value that cause it, e.g. ``"[identify] M = 100000"``
        (or the file, for a reader).
    need : str
        What needs the memory, e.g. ``"the regressor of 3750 samples x 300012 columns"``.
    detail : str, optional
        What the estimate includes, printed in parentheses after it.

    Raises
    ------
    ResourceError
        If ``nbytes`` exceeds :func:`memory_budget`, naming ``setting``, the estimate
        and the budget.
    WorkflowError
        If ``DEBIST_MEMORY_BUDGET_GB`` is invalid.

    References
    ----------
    psutil, ``virtual_memory``.
    """
    budget, source = _budget()
    if nbytes > budget:
        extra = f" ({detail})" if detail else ""
        raise ResourceError(
            f"{setting}: {need} needs about {format_bytes(nbytes)}{extra}; the memory budget "
            f"is {format_bytes(budget)} ({source})"
        )


# --------------------------------------------------------------------------- identification
def _terms(cfg: Any) -> tuple[int, tuple[str, ...], tuple[str, ...], bool]:
    """``M``, RBF and backbone terms, and whether m_q is identified, of an identify config."""
    return int(cfg.M), tuple(cfg.rbf), tuple(cfg.backbone), cfg.m_q == "identify"


def identify_columns(cfg: Any, n_inputs: int) -> tuple[int, int]:
    """Count the columns of the least squares of Eq. 40 without building it.

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings (``M``, ``rbf``, ``backbone``, ``m_q``, ``creep``,
        ``slip``).
    n_inputs : int
        Number of inputs v_1..v_N.

    Returns
    -------
    columns : int
        Regressor columns (the names :func:`debist.identify.fit.fit_rbf_model` reports).
    z_columns : int
        Those that depend on the friction state z (re-built in every T_z evaluation).

    References
    ----------
    Masoud & Maas 2025, Eq. 40; :func:`debist.model.terms.force_columns` and
    :func:`~debist.model.terms.input_columns` (one column per name).
    """
    p, _, p_z = _columns(cfg, n_inputs)
    return p, p_z


def _columns(cfg: Any, n_inputs: int) -> tuple[int, int, int]:
    """All columns, force columns (the left-hand block) and z columns."""
    M, rbf, backbone, identify_mass = _terms(cfg)
    force = M * (("c" in rbf) + ("d" in rbf)) + sum(b in backbone for b in _FORCE_SCALARS)
    force += M * (getattr(cfg, "creep", False) is not False)  # creep[i] (Eq. 26)
    force += getattr(cfg, "n_slip", 0)  # slip[e], the Maxwell-slip elements
    force += len(getattr(cfg, "inertia_powers", ()))  # inertia[a], the coefficients of m(q)
    z_cols = M * ("d" in rbf) + sum(b in backbone for b in _Z_TERMS)
    if identify_mass:
        return 1 + force, 1 + force, z_cols
    inputs = n_inputs * (M * ("g" in rbf) + sum(b in backbone for b in _INPUT_VECTORS))
    return force + inputs, force, z_cols


def _solve_elements(rows: int, cols: int) -> int:
    """float64 elements alive at the peak of the SVD solve (see :func:`identify_bytes`)."""
    k = min(rows, cols)
    return 3 * rows * cols + 2 * k * (rows + cols) + 5 * k * k


def identify_bytes(cfg: Any, n_inputs: int, rows: int, longest: int | None = None) -> int:
    """Estimate the peak memory of :func:`debist.identify.fit.fit_rbf_model`.

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings.
    n_inputs : int
        Number of inputs.
    rows : int
        Regressor rows: samples of all estimation records after ``trim``.
    longest : int, optional
        Samples of the longest record (its blocks are built one at a time); default
        ``rows``.

    Returns
    -------
    int
        The largest of the phases below [bytes].

    Notes
    -----
    The largest of six phases (support check, regressor build, T_z search, SVD solve,
    block bootstrap, and the Gaussian basis on the longest record or on the curves' grid of
    :data:`CURVE_GRID` positions), each counted in float64 elements of n rows, p columns
    and M centres; the formulas: docs/explanation/implementation.md.

    References
    ----------
    LAPACK Users' Guide, 3rd ed., dgesdd work space; numpy.linalg.svd and qr
    (``_umath_linalg`` buffers).
    """
    return _F8 * max(_identify_phases(cfg, n_inputs, rows, longest).values())


def _identify_phases(cfg: Any, n_inputs: int, rows: int, longest: int | None) -> dict[str, int]:
    """Elements of each phase of :func:`identify_bytes`, keyed by the setting that sizes it."""
    M = _terms(cfg)[0]
    p, p_force, p_z = _columns(cfg, n_inputs)
    n = int(rows)
    n_r = min(int(longest), n) if longest is not None else n
    block = M + 5 * p if cfg.lowpass is not None else M + 2 * p + p_force
    build = max(2 * n * p, (n - n_r) * p + n_r * block)
    # the Gaussian basis of the longest record and of the curves' grid: q - xi, its square
    # and the exponential, alive together (debist.model.basis.gaussian)
    sizes = [2 * n * M, build, _solve_elements(n, p), 3 * max(n_r, CURVE_GRID) * M]
    if cfg.T_z == "search" and p_z > 0:
        p_f = p - p_z
        sizes += [5 * n * p_f, 2 * n * p_f + 5 * n * p_z]
    phases = {f"[identify] M = {M}": max(sizes)}
    if getattr(cfg, "bootstrap", 0) > 0:
        blocks, B = math.ceil(n ** (2.0 / 3.0)), int(cfg.bootstrap)
        phases[f"[identify] bootstrap = {B}"] = (
            5 * n * p + blocks * p * p + 2 * B * p * p + B * blocks + 3 * B * BAND_GRID
        )
    return phases


def identify_setting(cfg: Any, n_inputs: int, rows: int, longest: int | None = None) -> str:
    """Name the setting to change: the bootstrap where the fit without it fits the budget.

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings.
    n_inputs, rows : int
        Inputs, and regressor rows (estimation samples after ``trim``).
    longest : int, optional
        Samples of the longest record; default ``rows``.

    Returns
    -------
    str
        ``"[identify] bootstrap = <B>"`` when the least squares without the bootstrap fits
        :func:`memory_budget` and the bootstrap's phase does not, else
        ``"[identify] M = <M>"``.

    References
    ----------
    Masoud & Maas 2025, Eq. 40; Kuensch 1989, Ann. Statist. 17(3) (block bootstrap).
    """
    phases = _identify_phases(cfg, n_inputs, rows, longest)
    first, *rest = phases
    if rest and _F8 * phases[first] <= memory_budget():
        return rest[0]
    return first


def check_identify(
    cfg: Any, n_inputs: int, rows: int, longest: int | None = None, setting: str | None = None
) -> None:
    """Refuse an identification whose least squares would exceed the memory budget.

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings.
    n_inputs : int
        Number of inputs.
    rows : int
        Regressor rows (estimation samples after ``trim``).
    longest : int, optional
        Samples of the longest record.
    setting : str, optional
        The key to name; default the setting that sizes the largest phase
        (``"[identify] M = <M>"``, or ``"[identify] bootstrap = <B>"`` when the bootstrap's
        replicates need the most).

    Raises
    ------
    ResourceError
        If :func:`identify_bytes` exceeds :func:`memory_budget`.

    References
    ----------
    Masoud & Maas 2025, Eq. 40.
    """
    p, _ = identify_columns(cfg, n_inputs)
    check_memory(
        identify_bytes(cfg, n_inputs, rows, longest),
        setting or identify_setting(cfg, n_inputs, rows, longest),
        f"the regressor of {rows} samples x {p} columns",
        "peak, with the SVD's copies",
    )


def identify_lower_bound(cfg: Any, n_inputs: int) -> int:
    """Memory the least squares needs at least, whatever the data [bytes].

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings.
    n_inputs : int
        Number of inputs.

    Returns
    -------
    int
        The SVD solve of :func:`identify_bytes` with as many rows as columns (a least-
        squares problem needs at least that many), ``12 p^2 x 8`` bytes, p columns;
        at least ``p^2 x 8``.

    References
    ----------
    Golub & Van Loan, Matrix Computations, 4th ed., Sec. 5.3 (overdetermined least
    squares needs rows >= columns).
    """
    p, _ = identify_columns(cfg, n_inputs)
    return _F8 * _solve_elements(p, p)


def check_identify_config(cfg: Any, n_inputs: int) -> None:
    """Data-free check of an ``[identify]`` section, usable when a workflow is loaded.

    Parameters
    ----------
    cfg : IdentifyConfig
        The ``[identify]`` settings.
    n_inputs : int
        Number of inputs (the ``v1..vN`` channels of the ingest section).

    Raises
    ------
    ResourceError
        If :func:`identify_lower_bound` exceeds the budget, naming ``[identify] M``.

    References
    ----------
    Masoud & Maas 2025, Eq. 40.
    """
    p, _ = identify_columns(cfg, n_inputs)
    check_memory(
        identify_lower_bound(cfg, n_inputs),
        f"[identify] M = {_terms(cfg)[0]}",
        f"the least squares of {p} columns (and so at least {p} samples)",
        "lower bound, whatever the data",
    )


# ------------------------------------------------------------------------------- free runs
def free_run_bytes(
    lengths: Sequence[int], n_inputs: int, n_states: int, substeps: int, batch_extra: int = 0
) -> int:
    """Estimate the peak memory of :func:`debist.simulate.freerun.simulate` [bytes].

    Parameters
    ----------
    lengths : sequence of int
        Samples of each record of the batch.
    n_inputs : int
        Inputs per record.
    n_states : int
        States of the model.
    substeps : int
        RK4 steps per sample interval actually used.
    batch_extra : int, optional
        float64 elements per trajectory of the model's right-hand side temporaries.

    Returns
    -------
    int
        The larger of the two phases below.

    Notes
    -----
    With B records of up to n samples and m = 2 (n - 1) substeps + 1 fine-grid points:
    input preparation keeps every record's padded fine inputs and then their stacked
    copy, 2 B m n_inputs (while a record is interpolated, the earlier ones, its FIR
    output and its padded copy: fewer); the integration keeps the fine inputs, the
    states and accelerations B n (n_states + 1) and the per-record result copies (states,
    q, q_dot, q_ddot).

    References
    ----------
    Hairer, Norsett & Wanner, Solving ODEs I, Sec. II.1 (RK4 with sub-steps).
    """
    B = len(lengths)
    n = max(lengths) if lengths else 0
    total = sum(int(v) for v in lengths)
    m = 2 * max(n - 1, 0) * int(substeps) + 1
    prepare = 2 * B * m * n_inputs
    integrate = B * m * n_inputs + B * n * (n_states + 1) + total * (n_states + 3)
    return _F8 * (max(prepare, integrate) + B * batch_extra)


def refine_bytes(
    windows: int,
    length: int,
    n_params: int,
    n_inputs: int,
    substeps: int,
    columns: int,
    M: int,
    n_states: int = 3,
) -> int:
    """Estimate the peak memory of :func:`debist.identify.refine.refine_model` [bytes].

    Parameters
    ----------
    windows, length : int
        Windows W and samples per window L.
    n_params : int
        Optimised parameters P (regressor columns, plus log T_z when refined).
    n_inputs : int
        Inputs.
    substeps : int
        RK4 sub-steps per sample of the window simulations.
    columns : int
        Regressor columns p (the right-hand side builds them for every trajectory).
    M : int
        RBF centres.
    n_states : int, optional
        Model states (3: q, q_dot, z).

    Returns
    -------
    int
        The larger of the Jacobian's batched simulation and the optimiser's step.

    Notes
    -----
    A Jacobian evaluation simulates B = (P + 1) W trajectories at once: the tiled fine
    inputs (``np.tile`` and its transient copy) 2 B m n_inputs (m = 2 (L - 1) substeps +
    1) beside the untiled W m n_inputs; the states and accelerations B L (n_states + 1),
    the per-trajectory result copies B L (n_states + 3) and the stacked positions and
    their errors 3 B L; the right-hand side's basis, force and input columns and their
    products, 2 B (2 M + 3 p). The trust-region step keeps the
    residuals (P + 1) W L, their differences and the Jacobian (2 P W L) and the SVD of
    the Jacobian (as in :func:`identify_bytes`).

    References
    ----------
    scipy.optimize.least_squares, method "trf" with ``tr_solver="exact"`` (SVD of J).
    """
    W, L, P = int(windows), int(length), int(n_params)
    B = (P + 1) * W
    m = 2 * max(L - 1, 0) * int(substeps) + 1
    sim = 2 * B * m * n_inputs + W * m * n_inputs + B * L * (2 * n_states + 7)
    sim += 2 * B * (2 * M + 3 * columns)
    step = (P + 1) * W * L + 2 * P * W * L + _solve_elements(W * L, P)
    return _F8 * max(sim, step)


def narx_bytes(rows: int, lag: int, degree: int, n_inputs: int) -> int:
    """Estimate the peak memory of the NARX peer's candidate regressor [bytes].

    Parameters
    ----------
    rows : int
        Samples of all records.
    lag : int
        Largest lag of q and of each input.
    degree : int
        Largest polynomial degree.
    n_inputs : int
        Inputs.

    Returns
    -------
    int
        ``8 x 5 rows C(lag (1 + n_inputs) + degree, degree)``: every monomial of degree <= d
        in the lagged outputs and inputs, as a matrix, and the copies FROLS and the
        validation make of it (measured: 192 MB, 4.5 matrices, for lag 6, degree 3, two
        inputs and 4000 samples, peak resident set of :func:`debist.model.narx.fit_narx`).

    References
    ----------
    Billings 2013, Nonlinear System Identification, Ch. 3 (FROLS); Lacerda, Andrade &
    Martins 2020, JOSS 5(54), 2384 (sysidentpy ``Polynomial`` basis).

    Examples
    --------
    >>> narx_bytes(1000, 3, 3, 2) == 8 * 5 * 1000 * 220
    True
    """
    terms = math.comb(int(lag) * (1 + int(n_inputs)) + int(degree), int(degree))
    return _F8 * 5 * int(rows) * terms


def sindy_terms(degree: int, n_inputs: int, input_terms: bool) -> int:
    """Count the library terms of :func:`debist.model.sindy.fit_sindy`.

    Parameters
    ----------
    degree : int
        Polynomial degree in q and q_dot.
    n_inputs : int
        Inputs h_1..h_N.
    input_terms : bool
        Whether every polynomial term is also multiplied by each input (else each input is
        one linear term).

    Returns
    -------
    int
        ``(d + 1)(d + 2) / 2`` monomials of degree <= d in (q, q_dot), times ``1 + N`` with
        the input terms, else plus N.

    References
    ----------
    Brunton, Proctor & Kutz 2016, PNAS 113(15) (SINDy with control); Kaptanoglu et al.
    2022, JOSS 7(69), 3994 (pysindy ``PolynomialLibrary``, ``GeneralizedLibrary``).

    Examples
    --------
    >>> sindy_terms(3, 2, True), sindy_terms(3, 2, False)
    (30, 12)
    """
    poly = (int(degree) + 1) * (int(degree) + 2) // 2
    return poly * (1 + n_inputs) if input_terms else poly + n_inputs


def sindy_bytes(rows: int, n_features: int) -> int:
    """Estimate the peak memory of :func:`debist.model.sindy.fit_sindy` [bytes].

    Parameters
    ----------
    rows : int
        Samples of all records.
    n_features : int
        Library terms.

    Returns
    -------
    int
        ``8 x 18 rows n_features``.

    Notes
    -----
    pysindy builds every sub-library's block, their tensor products and concatenation,
    sklearn's validated copies, the normalised library and STLSQ's ridge and unbiasing
    least squares for each of the two state equations: 14 to 17.5 blocks of rows x
    n_features float64 measured with tracemalloc (STLSQ and SR3, degree 3 and 5, with
    and without input terms; 20000 and 50000 samples), hence 18.

    References
    ----------
    Kaptanoglu et al. 2022, JOSS 7(69), 3994 (pysindy ``GeneralizedLibrary``, ``STLSQ``).
    """
    return _F8 * 18 * int(rows) * int(n_features)
