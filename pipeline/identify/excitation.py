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
        One row per RBF centre [unit of q]: hard counts ``n_total``, ``n_moving``,
        ``n_quasi_static``, ``n_inactive``, ``n_input<i>_active``; Eq. 38-weighted counts
        ``neff_*``; decisions ``supported_c``, ``supported_d``, ``supported_g<i>``.
    spectra : pandas.DataFrame
        One row per record and channel (``q``, ``h1 .. hN``): ``variance``, ``f_peak`` [Hz],
        ``n_lines``, ``bandwidth`` [Hz], ``df`` [Hz], ``single_line``, ``fundamental`` [Hz],
        ``harmonic``.
    single_frequency : list of str
        Records whose response q is one spectral line.
    periodic : list of str
        Records whose inputs and response repeat one period (harmonics of one fundamental).
    unsupported : dict of str to list of tuple of float
        Per curve the q intervals ``(a, b)`` [unit of q] of unsupported centres.
    transient_intervals : list of tuple of float
        q intervals ``(a, b)`` [unit of q] visited only in transit.
    warnings : list of str
        Plain-language warnings, q in ``unit_name``.
    sigma : float
        RBF width [unit of q].
    settings : dict
        The thresholds used (for the manifest; ``bin_width`` in the display unit).
    unit_scale, unit_name : float, str
        Display unit per unit of q, and its name.

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

    Coverage, frequency content and transient-only intervals: docs/explanation/implementation.md.

    Parameters
    ----------
    records : sequence of Record
        Estimation records: ``q`` (n,) [unit of q], ``q_dot`` (n,), ``v`` (n, n_inputs) [V].
    basis : RBFBasis
        Centres ``xi`` (M,) and width ``sigma`` [unit of q].
    input_map_kind : {"v2", "v"}, optional
        The input map h(v) of the model.
    rbf : sequence of str, optional
        The RBF curves of the model; warnings are issued for these only.
    min_samples : int, optional
        Fewest samples within one width of a centre for a supported curve.
    off_fraction, noise_factor : float, optional
        Thresholds of :func:`input_active`.
    moving_fraction : float, optional
        In motion where ``|q_dot|`` exceeds this fraction of its RMS over all records.
    fast_factor, quasi_static_fraction, bin_width : float, optional
        Transient check: transit threshold [robust SDs of q_dot], quasi-static share, bin [q].
    power_fraction, line_bins, nperseg : optional
        Spectral power share of the lines, widest line [bins], Welch segment [samples].
    unit_scale, unit_name : optional
        Display unit per unit of q (e.g. 1e3 for mm) and its name, for the warnings.

    Returns
    -------
    ExcitationReport

    Raises
    ------
    WorkflowError
        If records are missing or disagree, ``dt <= 0``, or a setting is out of range.

    References
    ----------
    Masoud & Maas 2025, Eq. 37-40; Ljung 1999, Sec. 13.2; Welch 1967, IEEE Trans. AU-15(2).
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

    The off level ``v_off`` is the median of the samples with ``|v_i|`` at most ``off_fraction``
    of its largest magnitude, ``s`` their robust noise (1.4826 times the median absolute
    deviation); a sample is active where
    ``|v_i - v_off| > max(noise_factor s, off_fraction max|v_i|)``. Why not a share of the
    largest value: docs/explanation/implementation.md.

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
    Masoud & Maas 2025, Eq. 37-40, Fig. 11a; Rousseeuw & Croux 1993, J. Am. Stat. Assoc. 88,
    1273-1283 (the MAD).

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
