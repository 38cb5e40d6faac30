"""Excitation check before identification: which curves of Eq. 37-40 the data can identify.

The RBF model of Masoud & Maas 2025 (Eq. 37-40),

    m_q q'' + c(q) q + d(q) z + (backbone) = sum_i g_i(q) h(v_i),

expands ``c``, ``d`` and ``g_i`` in Gaussian RBFs on centres ``xi_k`` (Eq. 38, 39). A weight
of centre ``k`` is informed only by the samples near ``xi_k``, and only if the regressor
column varies there: ``c`` needs samples, ``d`` samples in motion (``z`` follows ``q_dot``),
``g_i`` samples with input ``i`` active. Beyond the local coverage, the least squares needs
a persistently exciting experiment (Ljung 1999, Sec. 13.2): a response that is one sinusoid
satisfies ``q'' = -W^2 q``, so stiffness and mass (and, with ``z`` a phase-shifted copy, the
damping) cannot be told apart. And parts of the range crossed only during the fast
switching transients between the wells hold no quasi-static samples: the stiffness there
rests on the inertia and damping of those transients alone.

:func:`check_excitation` measures the three from the estimation records and returns an
:class:`ExcitationReport` with plain-language warnings.

Units: the tables, intervals and ``sigma`` of the report are in the records' unit of q
(SI, [m], as the records carry it); the warnings and :meth:`ExcitationReport.to_summary`
are in a display unit given by ``unit_scale`` and ``unit_name`` (e.g. ``1e3, "mm"``, the
factor of :func:`debist.validate.freerun.report_factor`).

References
----------
Masoud & Maas 2025, Eq. 37-40; L. Ljung, System Identification: Theory for the User, 2nd
ed., Prentice Hall 1999, Sec. 13.2 (informative experiments, persistence of excitation);
P. D. Welch, IEEE Trans. Audio Electroacoust. 15(2), 70-73, 1967 (averaged periodograms).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import lazy_loader as lazy
import numpy as np

from debist.core import metrics
from debist.core.errors import WorkflowError
from debist.identify.spectrum import (
    is_periodic,
    periodic_warning,
    record_spectra,
    under_excitation,
)
from debist.model.basis import RBFBasis, gaussian
from debist.model.terms import RBF_TERMS
from debist.model.termtable import input_map

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

if TYPE_CHECKING:  # the fit module may import this one
    from debist.identify.fit import Record

__all__ = [
    "FAST_FACTOR",
    "NOISE_FACTOR",
    "OFF_FRACTION",
    "ExcitationReport",
    "check_excitation",
    "input_active",
    "quasi_static",
    "under_excitation",  # (from debist.identify.spectrum)
]

#: Robust standard deviation of a zero-mean normal sample from the median of its magnitude.
_MEDIAN_TO_SD = 1.4826
#: Quasi-static threshold of :func:`quasi_static` in robust scales of |q_dot|.
FAST_FACTOR = 3.0
#: An input is "off" near zero: within this fraction of its largest magnitude (the channel's own
#: scale), and "active" where it stands out of its off level by more than this fraction too.
OFF_FRACTION = 0.03
#: ... and by more than this many robust standard deviations of the off level's noise.
NOISE_FACTOR = 6.0


@dataclass(frozen=True)
class ExcitationReport:
    """What the estimation data can identify (result of :func:`check_excitation`).

    Attributes
    ----------
    table : pandas.DataFrame
        One row per RBF centre, columns ``centre`` [unit of q]; hard counts of the samples
        with ``|q - xi_k| <= sigma``: ``n_total``, ``n_moving`` (``|q_dot|`` above
        ``moving_fraction`` of its RMS), ``n_quasi_static`` (not in transit, see
        ``transient_intervals``), ``n_inactive`` (every input inactive),
        ``n_input1_active .. n_inputN_active``; the same weighted by the Gaussian of Eq. 38
        (effective sample counts) ``neff_total``, ``neff_moving``, ``neff_inactive``,
        ``neff_input1_active ..``; and the decisions ``supported_c``, ``supported_d``,
        ``supported_g1 .. supported_gN`` (count at least ``min_samples``).
    spectra : pandas.DataFrame
        One row per record and channel (``q``, ``h1 .. hN`` = ``h(v_i)``): ``record``,
        ``channel``, ``variance`` [unit^2], ``f_peak`` [Hz] (power-weighted centre of the
        strongest cluster), ``n_lines`` (clusters of spectral bins carrying
        ``power_fraction`` of the power), ``bandwidth`` [Hz] (their total width), ``df``
        [Hz] (resolution), ``single_line`` (bool), ``fundamental`` [Hz] (centre of the
        lowest cluster), ``harmonic`` (bool: every cluster a line, at most ``line_bins``
        wide, at a whole multiple of it).
    single_frequency : list of str
        Records whose response q is one spectral line.
    periodic : list of str
        Records that are not single lines but whose inputs and response repeat one period:
        q and every excited input carry their power in harmonics of one fundamental.
    unsupported : dict of str to list of tuple of float
        Per curve (``c``, ``d``, ``g1`` ..) the q intervals ``(a, b)`` [unit of q] of merged
        runs of unsupported centres, ``(xi_a - sigma, xi_b + sigma)``.
    transient_intervals : list of tuple of float
        q intervals ``(a, b)`` [unit of q] visited only in transit (no quasi-static samples).
    warnings : list of str
        Plain-language warnings, q in ``unit_name``.
    sigma : float
        RBF width [unit of q].
    settings : dict
        The thresholds used (for the manifest; ``bin_width`` in the display unit).
    unit_scale : float
        Display unit per unit of q.
    unit_name : str
        Display unit.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40; Ljung 1999, Sec. 13.2.
    """

    table: pd.DataFrame
    spectra: pd.DataFrame
    single_frequency: list[str]
    unsupported: dict[str, list[tuple[float, float]]]
    transient_intervals: list[tuple[float, float]]
    warnings: list[str]
    sigma: float
    settings: dict = field(default_factory=dict)
    unit_scale: float = 1.0
    unit_name: str = "m"
    periodic: list[str] = field(default_factory=list)

    def to_summary(self) -> dict:
        """Return a JSON-able summary, q values in the display unit.

        Returns
        -------
        dict
            ``unit``, ``sigma``, ``settings``, ``centres`` (the table as a list of row
            dicts, ``centre`` scaled), ``unsupported`` (curve -> list of ``[a, b]``),
            ``transient_only`` (list of ``[a, b]``), ``spectra`` (list of row dicts),
            ``single_frequency``, ``periodic`` and ``warnings``.
        """
        s = self.unit_scale
        table = self.table.assign(centre=self.table["centre"] * s)
        return {
            "unit": self.unit_name,
            "sigma": float(self.sigma * s),
            "settings": dict(self.settings),
            "centres": json.loads(table.to_json(orient="records")),
            "unsupported": {
                k: [[float(a * s), float(b * s)] for a, b in v] for k, v in self.unsupported.items()
            },
            "transient_only": [[float(a * s), float(b * s)] for a, b in self.transient_intervals],
            "spectra": json.loads(self.spectra.to_json(orient="records")),
            "single_frequency": list(self.single_frequency),
            "periodic": list(self.periodic),
            "warnings": list(self.warnings),
        }


def check_excitation(
    records: Sequence[Record],
    basis: RBFBasis,
    input_map_kind: str = "v2",
    *,
    rbf: Sequence[str] = RBF_TERMS,
    min_samples: int = 10,
    off_fraction: float = OFF_FRACTION,
    noise_factor: float = NOISE_FACTOR,
    moving_fraction: float = 0.1,
    fast_factor: float = FAST_FACTOR,
    quasi_static_fraction: float = 0.05,
    bin_width: float | None = None,
    power_fraction: float = 0.95,
    line_bins: int = 6,
    nperseg: int | None = None,
    unit_scale: float = 1.0,
    unit_name: str = "m",
) -> ExcitationReport:
    """Check which curves of the RBF model the estimation records can identify.

    Three checks, all deterministic:

    1. *Coverage per centre.* Samples with ``|q - xi_k| <= sigma`` (as
       :meth:`RBFBasis.support`) are counted in total, in motion (``|q_dot|`` above
       ``moving_fraction`` of the pooled RMS of ``q_dot``), with input ``i`` active
       (:func:`input_active` on the pooled inputs: ``v_i`` clearly off its own off level,
       sub-threshold levels included) and with every input inactive; the effective
       counts weight each sample by ``exp(-(q - xi_k)^2 / (2 sigma^2))`` (Eq. 38, without
       clipping). Centre ``k`` supports ``c`` if
       ``n_total >= min_samples``, ``d`` if ``n_moving >= min_samples`` and ``g_i`` if
       ``n_input<i>_active >= min_samples``.
    2. *Frequency content.* Per record, the Welch PSD (Hann window, ``nperseg`` samples,
       half overlap, mean removed per segment, DC bin dropped) of q and of every ``h(v_i)``.
       The fewest bins carrying ``power_fraction`` of the power are grouped into clusters
       (bins at most two apart join); ``n_lines`` is the number of clusters and
       ``bandwidth`` their total width. A channel is a *single line* if it has one cluster,
       no wider than ``line_bins`` bins (the Hann main lobe is 4 bins) and resolved (its
       band at most half its frequency, so a line needs about 16 periods in the record
       at the default ``nperseg``). A record whose q is a single line is warned about: one
       frequency cannot separate stiffness from mass and damping (Ljung 1999, Sec. 13.2).
       A record is *periodic* if q and every excited input (variance above 1e-6 of the most
       varied one's: an idle input's monitor noise does not count) have each cluster a line
       (at most ``line_bins`` bins) centred within
       1.5 bins of a whole multiple of the lowest one and share that fundamental: a single
       tone through a nonlinearity (its harmonics), whose data show one periodic orbit and
       excite no other frequency (the input is persistently exciting of a low order only,
       Ljung 1999, Sec. 13.2); it is warned about the same way.
    3. *Transient-only intervals.* A sample is in transit if ``|q_dot|`` exceeds
       ``fast_factor`` times a robust speed scale of its record: 1.4826 times the median
       of ``|q_dot|`` (the standard deviation of zero-mean normal velocities; the median is
       set by the dwelling, not by the brief transits), at least 1 % of the record's
       largest ``|q_dot|``. The pooled q range is cut into bins of ``bin_width``; the
       window ``+-sigma`` around a bin (the reach of one RBF) is *transient-only* if it
       holds samples in transit and fewer than ``min_samples`` quasi-static ones, or
       quasi-static ones below ``quasi_static_fraction`` of its samples. Runs of such bins
       are merged into the union of their windows, clipped to the data range (as the
       coverage intervals ``[xi_a - sigma, xi_b + sigma]``). The window bridges unvisited
       bins between sparse fast samples; the far end of an overshoot, slow only at its few
       turning points, is flagged with the way to it.

    Parameters
    ----------
    records : sequence of Record
        Estimation records: ``q`` (n,) [unit of q], ``q_dot`` (n,) [unit/s], ``v``
        (n, n_inputs) [V], ``dt`` [s]. All with the same number of inputs.
    basis : RBFBasis
        Centres ``xi`` (M,) and width ``sigma`` [unit of q].
    input_map_kind : {"v2", "v"}, optional
        The input map h(v) of the model (``v^2`` for DE actuators).
    rbf : sequence of str, optional
        The RBF curves of the model (subset of ``("c", "d", "g")``); warnings are issued for
        these only. The table always has every column.
    min_samples : int, optional
        Fewest samples within one width of a centre for a supported curve.
    off_fraction : float, optional
        Off band and activity floor of :func:`input_active`, a fraction of ``max |v_i|``
        over all records, in (0, 1).
    noise_factor : float, optional
        Activity threshold of :func:`input_active` in robust standard deviations of the
        input's off-level noise.
    moving_fraction : float, optional
        A sample is in motion where ``|q_dot|`` exceeds this fraction of the RMS of
        ``q_dot`` over all records.
    fast_factor : float, optional
        Transit threshold in robust standard deviations of the record's ``q_dot``.
    quasi_static_fraction : float, optional
        A window is transient-only if fewer than this fraction of its samples (or fewer
        than ``min_samples``) are quasi-static.
    bin_width : float, optional
        Bin width of the transient check [unit of q]; default ``sigma / 2``.
    power_fraction : float, optional
        Share of the spectral power that defines the lines and the bandwidth, in (0, 1).
    line_bins : int, optional
        Widest cluster [bins] that still counts as one spectral line.
    nperseg : int, optional
        Welch segment length [samples]; default half the record (three half-overlapping
        segments; at least 256 samples, at most the record).
    unit_scale : float, optional
        Display unit per unit of q (e.g. 1e3 for q in m shown in mm); warnings and summary.
    unit_name : str, optional
        Display unit name.

    Returns
    -------
    ExcitationReport

    Raises
    ------
    WorkflowError
        If there are no records, the records disagree in their number of inputs, a
        record's lengths differ or its ``dt`` is not positive, a setting is out of range
        (``off_fraction``, ``noise_factor`` as :func:`input_active`) or ``input_map_kind``
        is unknown.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40; L. Ljung, System Identification: Theory for the User,
    2nd ed., 1999, Sec. 13.2 (persistence of excitation); P. D. Welch, IEEE Trans. Audio
    Electroacoust. 15(2), 70-73, 1967 (PSD estimate, :func:`scipy.signal.welch`).

    Examples
    --------
    >>> from debist.identify.fit import Record
    >>> from debist.model.basis import RBFBasis
    >>> t = np.arange(0, 20.0, 0.01)
    >>> q = 0.01 * np.sin(2 * np.pi * 1.5 * t)
    >>> v = np.full((t.size, 1), 100.0)
    >>> rec = Record("sine", q, np.gradient(q, 0.01), np.zeros_like(q), v, 0.01)
    >>> rep = check_excitation([rec], RBFBasis.equidistant(-0.01, 0.01, 5, 0.5), rbf=("c", "d"))
    >>> rep.single_frequency
    ['sine']
    """
    _validate(
        records,
        moving_fraction,
        power_fraction,
        quasi_static_fraction,
        min_samples=min_samples,
        line_bins=line_bins,
        fast_factor=fast_factor,
        bin_width=bin_width,
    )
    n_inputs = np.asarray(records[0].v).reshape(len(records[0].q), -1).shape[1]
    q = np.concatenate([np.asarray(r.q, dtype=float) for r in records])
    q_dot = np.concatenate([np.asarray(r.q_dot, dtype=float) for r in records])
    v = np.vstack([np.asarray(r.v, dtype=float).reshape(len(r.q), -1) for r in records])
    hv = input_map(v, input_map_kind)
    slow = np.concatenate([quasi_static(r.q_dot, fast_factor) for r in records])

    rms = metrics.rms(q_dot) if q_dot.size else 0.0
    masks = {"total": np.ones(q.size, dtype=bool), "moving": np.abs(q_dot) > moving_fraction * rms}
    masks["quasi_static"] = slow
    hmax = np.abs(hv).max(axis=0) if hv.size else np.zeros(n_inputs)
    active = input_active(v, off_fraction=off_fraction, noise_factor=noise_factor)
    masks["inactive"] = ~active.any(axis=1)
    for j in range(n_inputs):
        masks[f"input{j + 1}_active"] = active[:, j]
    table = _coverage(q, basis, masks, min_samples, n_inputs)

    sigma = float(basis.sigma)
    unsupported = {"c": _runs(basis.xi, sigma, ~table["supported_c"].to_numpy())}
    unsupported["d"] = _runs(basis.xi, sigma, ~table["supported_d"].to_numpy())
    for j in range(n_inputs):
        col = table[f"supported_g{j + 1}"].to_numpy()
        unsupported[f"g{j + 1}"] = _runs(basis.xi, sigma, ~col)

    width = float(bin_width) if bin_width is not None else sigma / 2.0
    transient = _transient_intervals(q, slow, width, sigma, min_samples, quasi_static_fraction)

    spectra = record_spectra(records, input_map_kind, nperseg, power_fraction, line_bins)
    single = [
        str(row.record)
        for row in spectra.itertuples()
        if row.channel == "q" and bool(row.single_line)
    ]
    periodic = [
        name for name in dict.fromkeys(spectra["record"].astype(str)) if name not in single
        and is_periodic(spectra[spectra["record"] == name])
    ]  # fmt: skip

    fmt = _Formatter(sigma, unit_scale, unit_name)
    settings = {
        "input_map": input_map_kind,
        "min_samples": int(min_samples),
        "off_fraction": float(off_fraction),
        "noise_factor": float(noise_factor),
        "moving_fraction": float(moving_fraction),
        "fast_factor": float(fast_factor),
        "quasi_static_fraction": float(quasi_static_fraction),
        "bin_width": float(width * unit_scale),
        "power_fraction": float(power_fraction),
        "line_bins": int(line_bins),
    }
    warnings = _warnings(
        table, basis, rbf, n_inputs, hmax, transient, spectra, single, settings, fmt
    )
    warnings += [periodic_warning(spectra, name) for name in periodic]
    return ExcitationReport(
        table=table,
        spectra=spectra,
        single_frequency=single,
        periodic=periodic,
        unsupported=unsupported,
        transient_intervals=transient,
        warnings=warnings,
        sigma=sigma,
        settings=settings,
        unit_scale=float(unit_scale),
        unit_name=unit_name,
    )


def _validate(
    records,
    moving_fraction,
    power_fraction,
    qs_fraction,
    *,
    min_samples,
    line_bins,
    fast_factor,
    bin_width,
) -> None:
    if not records:
        raise WorkflowError("no estimation records to check the excitation of")
    n_inputs = {np.asarray(r.v).reshape(len(r.q), -1).shape[1] for r in records}
    if len(n_inputs) != 1:
        raise WorkflowError(
            f"the estimation records disagree in their number of inputs: {sorted(n_inputs)}"
        )
    for r in records:
        if not r.dt > 0:
            raise WorkflowError(f"record '{r.name}': sample time dt must be positive, got {r.dt!r}")
        if not (len(r.q) == len(r.q_dot) == np.asarray(r.v).shape[0]):
            raise WorkflowError(
                f"record '{r.name}': q, q_dot and v differ in length "
                f"({len(r.q)}, {len(r.q_dot)}, {np.asarray(r.v).shape[0]})"
            )
    for name, value, hi_open in (
        ("moving_fraction", moving_fraction, True),
        ("quasi_static_fraction", qs_fraction, False),
    ):
        if not (0.0 <= value < 1.0 or (not hi_open and value == 1.0)):
            raise WorkflowError(f"`{name}` must lie in [0, 1), got {value!r}")
    if not 0.0 < power_fraction < 1.0:
        raise WorkflowError(f"`power_fraction` must lie in (0, 1), got {power_fraction!r}")
    for name, value in (("min_samples", min_samples), ("line_bins", line_bins)):
        if int(value) != value or value < 1:
            raise WorkflowError(f"`{name}` must be a positive integer, got {value!r}")
    for name, value in (("fast_factor", fast_factor), ("bin_width", bin_width)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise WorkflowError(f"`{name}` must be positive, got {value!r}")


def quasi_static(q_dot: np.ndarray, fast_factor: float = FAST_FACTOR) -> np.ndarray:
    """Flag the quasi-static samples of one record.

    A sample is quasi-static when ``|q_dot|`` is within ``fast_factor`` robust scales of the
    record's speed: 1.4826 times the median of ``|q_dot|`` (the normal-consistent median
    absolute value; Rousseeuw & Croux 1993, J. Am. Stat. Assoc. 88, 1273-1283), but at least
    1 % of its largest ``|q_dot|``. A switching transit between the wells is not quasi-static.

    Parameters
    ----------
    q_dot : ndarray, shape (n,)
        Velocity of one record [unit of q / s].
    fast_factor : float, optional
        Threshold in robust scales (default :data:`FAST_FACTOR`).

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the sample is quasi-static.
    """
    x = np.abs(np.asarray(q_dot, dtype=float))
    if x.size == 0:
        return np.zeros(0, dtype=bool)
    scale = max(_MEDIAN_TO_SD * float(np.median(x)), 0.01 * float(np.max(x)))
    return x <= fast_factor * scale


def input_active(
    v: np.ndarray,
    *,
    off_fraction: float = OFF_FRACTION,
    noise_factor: float = NOISE_FACTOR,
) -> np.ndarray:
    """Flag the samples at which each input excites the beam, sub-threshold levels included.

    ``g_i`` of Eq. 37 multiplies ``h(v_i)``: a sample informs ``g_i(q)`` wherever
    ``g_i(q) h(v_i)`` is not negligible against the noise of the regression (Eq. 40), not
    only where the input switches the beam. A threshold relative to the largest ``h(v_i)``
    (e.g. 10 %: 0.95 kV of a 3 kV pulse) discards exactly the sub-threshold excitation
    (0.2-1 kV) a profile holds to identify ``g_i`` near the wells. So the input's activity is
    decided against its own off level, from the data:

    1. *Off level.* The samples with ``|v_i|`` at most ``off_fraction`` of its largest
       magnitude are the candidates for "off"; their median ``v_off`` is the off level and
       ``s = 1.4826 median |v_i - v_off|`` over them its noise (the normal-consistent median
       absolute deviation; Rousseeuw & Croux 1993). Without such samples ``v_off = s = 0``.
    2. *Active.* ``|v_i - v_off| > max(noise_factor s, off_fraction max|v_i|)``: clearly
       above the channel's noise, and above a floor at the channel's own scale, which keeps
       a driver's offset or leakage from counting (20 V of a 1.8 kV channel does not). At
       the defaults and ``h = v^2`` the floor is 0.09 % of the largest ``h`` (90 V of a
       3 kV maximum); 0.2 kV of a 3 kV maximum (0.44 % of the largest ``h``) counts.

    The decision is made on ``v`` (the logged channel), so it holds for any input map: for
    ``h = v^2`` and ``h = v`` alike the force ``g_i h(v_i)`` is non-zero exactly where
    ``v_i`` leaves zero. An input that is zero throughout is never active.

    Parameters
    ----------
    v : ndarray, shape (n, n_inputs)
        Input channels of the pooled estimation records [V, or the input's own unit].
    off_fraction : float, optional
        Off band and activity floor as a fraction of ``max |v_i|``, in (0, 1).
    noise_factor : float, optional
        Activity threshold in robust standard deviations of the off level's noise (> 0).

    Returns
    -------
    ndarray of bool, shape (n, n_inputs)
        True where input ``i`` is active.

    Raises
    ------
    WorkflowError
        If ``off_fraction`` is not in (0, 1) or ``noise_factor`` is not positive.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40 (``g_i(q) h(v_i)``), Fig. 11a (switching pulses and
    sub-threshold excitation); P. J. Rousseeuw & C. Croux, J. Am. Stat. Assoc. 88,
    1273-1283, 1993 (the MAD).

    Examples
    --------
    >>> v = np.array([[0.5], [-0.4], [0.3], [200.0], [3000.0], [0.0]])
    >>> input_active(v)[:, 0].tolist()
    [False, False, False, True, True, False]
    """
    if not 0.0 < off_fraction < 1.0:
        raise WorkflowError(f"`off_fraction` must lie in (0, 1), got {off_fraction!r}")
    if not (np.isfinite(noise_factor) and noise_factor > 0):
        raise WorkflowError(f"`noise_factor` must be positive, got {noise_factor!r}")
    v = np.asarray(v, dtype=float)
    v = v.reshape(v.shape[0], -1)
    out = np.zeros(v.shape, dtype=bool)
    for j in range(v.shape[1]):
        x = v[:, j]
        peak = float(np.max(np.abs(x), initial=0.0))
        if not peak > 0:
            continue
        off = x[np.abs(x) <= off_fraction * peak]
        level = float(np.median(off)) if off.size else 0.0
        noise = _MEDIAN_TO_SD * float(np.median(np.abs(off - level))) if off.size else 0.0
        out[:, j] = np.abs(x - level) > max(noise_factor * noise, off_fraction * peak)
    return out


def _coverage(q, basis, masks, min_samples, n_inputs) -> pd.DataFrame:
    """Count per centre (one centre at a time: memory O(n), not O(n M))."""
    xi = np.asarray(basis.xi, dtype=float)
    weighted = [name for name in masks if name != "quasi_static"]
    counts = {name: np.zeros(xi.size, dtype=int) for name in masks}
    neff = {name: np.zeros(xi.size) for name in weighted}
    for k, centre in enumerate(xi):
        near = np.abs(q - centre) <= basis.sigma
        gauss = gaussian(q - centre, basis.sigma)
        for name, mask in masks.items():
            counts[name][k] = np.count_nonzero(near & mask)
            if name in neff:
                neff[name][k] = float(gauss[mask].sum())
    cols: dict[str, np.ndarray] = {"centre": xi}
    cols |= {f"n_{name}": c for name, c in counts.items()}
    cols |= {f"neff_{name}": c for name, c in neff.items()}
    cols["supported_c"] = cols["n_total"] >= min_samples
    cols["supported_d"] = cols["n_moving"] >= min_samples
    for j in range(n_inputs):
        cols[f"supported_g{j + 1}"] = cols[f"n_input{j + 1}_active"] >= min_samples
    return pd.DataFrame(cols)


def _index_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Return the first and last index of every run of True in ``flags``."""
    padded = np.concatenate([[False], np.asarray(flags, dtype=bool), [False]])
    change = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b) - 1) for a, b in zip(change[::2], change[1::2], strict=True)]


def _runs(xi: np.ndarray, sigma: float, bad: np.ndarray) -> list[tuple[float, float]]:
    """Merge runs of flagged centres into ``(xi_a - sigma, xi_b + sigma)``."""
    return [(float(xi[a] - sigma), float(xi[b] + sigma)) for a, b in _index_runs(bad)]


def _transient_intervals(q, slow, width, sigma, min_samples, fraction):
    """Merge the windows ``+-sigma`` of grid bins that hold transit but hardly any rest."""
    if q.size == 0:
        return []
    lo, hi = float(q.min()), float(q.max())
    n_bins = max(1, math.ceil((hi - lo) / width))
    edges = lo + width * np.arange(n_bins + 1)
    mid = 0.5 * (edges[:-1] + edges[1:])

    def window_count(x):
        x = np.sort(x)
        return np.searchsorted(x, mid + sigma, "right") - np.searchsorted(x, mid - sigma, "left")

    n_all, n_slow = window_count(q), window_count(q[slow])
    flagged = (n_all > n_slow) & ((n_slow < min_samples) | (n_slow < fraction * n_all))
    return [
        (max(lo, float(mid[a] - sigma)), min(hi, float(mid[b] + sigma)))
        for a, b in _index_runs(flagged)
    ]


def thin_data(report: ExcitationReport) -> bool:
    """Whether a record of the report is one spectral line or one repeated period.

    Parameters
    ----------
    report : ExcitationReport
        The excitation check of the estimation records (:func:`check_excitation`).

    Returns
    -------
    bool
        True if any record is in ``single_frequency`` or ``periodic``.

    References
    ----------
    Ljung 1999, System Identification, 2nd ed., Sec. 13.2 (persistent excitation).
    """
    return bool(report.single_frequency or report.periodic)


@dataclass(frozen=True)
class _Formatter:
    """q intervals in the display unit, to a tenth of the RBF width."""

    sigma: float
    scale: float
    unit: str

    def num(self, x: float) -> str:
        """One q value [unit of q] in the display unit, without the unit name."""
        width = abs(self.sigma * self.scale)
        digits = max(0, 1 - math.floor(math.log10(width))) if width > 0 else 3
        return f"{x * self.scale:.{digits}f}"

    def value(self, x: float) -> str:
        """One q value [unit of q] with the unit name."""
        return self.num(x) + (f" {self.unit}" if self.unit else "")

    def __call__(self, intervals: Sequence[tuple[float, float]]) -> str:
        parts = [f"[{self.num(a)}, {self.num(b)}]" for a, b in intervals]
        return " and ".join(parts) + (f" {self.unit}" if self.unit else "")


def _warnings(table, basis, rbf, n_inputs, hmax, transient, spectra, single, settings, fmt):
    """Plain-language warnings, in the order: coverage, d, g_i, transients, spectrum."""
    xi, sigma, n_min = basis.xi, basis.sigma, settings["min_samples"]
    curves = [c for c in RBF_TERMS if c in rbf and c != "g"]
    if "g" in rbf:
        curves += [f"g{j + 1}" for j in range(n_inputs)]
    has_data = table["supported_c"].to_numpy()
    out = []
    empty = _runs(xi, sigma, ~has_data)
    if empty and curves:
        out.append(
            f"no data: fewer than {n_min} samples within sigma = {fmt.value(sigma)} of the "
            f"centres for q in {fmt(empty)}: {', '.join(curves)} there "
            f"{'is' if len(curves) == 1 else 'are'} not identified"
        )
    if "d" in rbf:
        still = _runs(xi, sigma, has_data & ~table["supported_d"].to_numpy())
        if still:
            out.append(
                f"d: q barely moves (fewer than {n_min} samples with |q_dot| above "
                f"{100 * settings['moving_fraction']:g} % of its RMS) for q in {fmt(still)}: "
                "d there is not identified"
            )
    if "g" in rbf:
        for j in range(n_inputs):
            g = f"g{j + 1}"
            if not hmax[j] > 0:
                out.append(
                    f"{g}: input {j + 1} is zero in every estimation record: {g} is not identified"
                )
                continue
            idle = _runs(xi, sigma, has_data & ~table[f"supported_{g}"].to_numpy())
            if idle:
                out.append(
                    f"{g}: input {j + 1} is never active (fewer than {n_min} samples with "
                    f"v_{j + 1} off its off level by more than {settings['noise_factor']:g} "
                    f"robust standard deviations of its noise and "
                    f"{100 * settings['off_fraction']:g} % of its maximum) "
                    f"for q in {fmt(idle)}: {g} there is not identified"
                )
    if transient:
        out.append(
            f"transient only: q in {fmt(transient)} is crossed only in transit: within sigma "
            f"of it fewer than {n_min} samples (or under "
            f"{100 * settings['quasi_static_fraction']:g} %) are quasi-static (|q_dot| below "
            f"{settings['fast_factor']:g} robust standard deviations of their record), so the "
            "curves there rest on the switching transients alone"
        )
    for name in single:
        rows = spectra[spectra["record"] == name]
        q_row = rows[rows["channel"] == "q"].iloc[0]
        inputs = rows[(rows["channel"] != "q") & (rows["variance"] > 0)]
        same = (
            " (and so do its inputs)" if len(inputs) and bool(inputs["single_line"].all()) else ""
        )
        out.append(
            f"record '{name}': q carries {100 * settings['power_fraction']:g} % of its power in "
            f"one spectral line at {q_row['f_peak']:.3g} Hz{same}: a single-frequency "
            "excitation cannot separate stiffness from mass and damping; excite with a "
            "multisine, a chirp or band-limited noise"
        )
    return out
