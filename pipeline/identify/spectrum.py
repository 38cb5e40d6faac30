"""Spectral lines of the estimation records: a single line, one repeated period, or broad.

A persistently exciting experiment spreads its power over frequencies; a response that is one
sinusoid, or one period repeated (a single tone through the bistable nonlinearity: its
harmonics only), cannot separate stiffness from mass and damping (Ljung 1999, Sec. 13.2).
Each channel's Welch PSD (Hann window, mean removed per segment, DC bin dropped) is reduced
to the clusters of bins that carry ``power_fraction`` of its power (:func:`channel_lines`);
the excitation check (:func:`debist.identify.excitation.check_excitation`) warns about such
records and the validate stage's verdicts say so (:func:`under_excitation`).

References
----------
L. Ljung, System Identification: Theory for the User, 2nd ed., Prentice Hall 1999, Sec. 13.2;
P. D. Welch, IEEE Trans. Audio Electroacoust. 15(2), 70-73, 1967 (averaged periodograms).
"""

from __future__ import annotations

import math

import lazy_loader as lazy
import numpy as np

from debist.model.termtable import input_map

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")
signal = lazy.load("scipy.signal", suppress_warning=True)

__all__ = [
    "IDLE_INPUT",
    "channel_lines",
    "default_nperseg",
    "is_periodic",
    "periodic_warning",
    "record_spectra",
    "under_excitation",
]

#: A line is resolved if its band is at most this fraction of its frequency (else it is
#: the low-frequency end of a broad spectrum, e.g. the slow switching between the wells).
_LINE_RESOLVED = 0.5
#: Shortest record for a spectrum [samples].
_MIN_SPECTRUM = 32
#: An input whose h(v_i) varies by less than this share of the most varied input's variance
#: is idle (its monitor's noise only) and does not count in the periodicity check.
IDLE_INPUT = 1e-6


def default_nperseg(n: int) -> int:
    """Welch segment length [samples] for a record of ``n`` samples: half of it, 256 to ``n``."""
    return min(n, max(256, n // 2))


def channel_lines(x, fs, nperseg, power_fraction, line_bins) -> dict:
    """Summarise the spectral lines of one channel from its Welch PSD.

    Parameters
    ----------
    x : array_like, shape (n,)
        The channel [its unit].
    fs : float
        Sample rate [Hz].
    nperseg : int or None
        Welch segment length [samples]; None: :func:`default_nperseg`.
    power_fraction : float
        Share of the power the fewest bins must carry.
    line_bins : int
        Widest cluster [bins] that counts as a line.

    Returns
    -------
    dict
        ``variance``, ``f_peak`` [Hz], ``n_lines``, ``bandwidth`` [Hz], ``df`` [Hz],
        ``single_line``, ``fundamental`` [Hz] and ``harmonic``
        (:class:`debist.identify.excitation.ExcitationReport`, ``spectra``).

    References
    ----------
    Welch 1967, IEEE Trans. Audio Electroacoust. 15(2), 70-73; Ljung 1999, Sec. 13.2.
    """
    x = np.asarray(x, dtype=float)
    out = {
        "variance": float(np.var(x)) if x.size else 0.0,
        "f_peak": math.nan,
        "n_lines": 0,
        "bandwidth": math.nan,
        "df": math.nan,
        "single_line": False,
        "fundamental": math.nan,
        "harmonic": False,
    }
    if x.size < _MIN_SPECTRUM or not np.ptp(x) > 0:
        return out
    seg = min(x.size, int(nperseg) if nperseg else default_nperseg(x.size))
    f, p = signal.welch(x, fs=fs, window="hann", nperseg=seg, detrend="constant")
    f, p = f[1:], p[1:]
    out["df"] = fs / seg
    total = float(p.sum())
    if not total > 0:
        return out
    order = np.argsort(-p, kind="stable")
    k = min(p.size, int(np.searchsorted(np.cumsum(p[order]), power_fraction * total)) + 1)
    sel = np.sort(order[:k])
    clusters = np.split(sel, np.flatnonzero(np.diff(sel) > 2) + 1)
    strongest = next(c for c in clusters if order[0] in c)
    out["f_peak"] = float(np.average(f[strongest], weights=p[strongest]))
    out["n_lines"] = len(clusters)
    out["bandwidth"] = float(k * fs / seg)
    narrow = int(sel[-1] - sel[0] + 1) <= line_bins
    resolved = out["bandwidth"] <= _LINE_RESOLVED * out["f_peak"]
    out["single_line"] = len(clusters) == 1 and narrow and resolved
    centres = np.array([np.average(f[c], weights=p[c]) for c in clusters])
    f0 = float(centres.min())
    whole = np.maximum(np.round(centres / f0), 1.0)
    out["fundamental"] = f0
    lines = all(int(c[-1] - c[0] + 1) <= line_bins for c in clusters)  # lines, not bands
    out["harmonic"] = lines and bool(np.all(np.abs(centres - whole * f0) <= 1.5 * out["df"]))
    return out


def under_excitation(summary: dict) -> str:
    """Say why the estimation data cannot separate the model's terms, or ``""``.

    Parameters
    ----------
    summary : dict
        The ``excitation`` entry of the identify summary (:meth:`ExcitationReport.to_summary`).

    Returns
    -------
    str
        E.g. ``"one spectral line at 2 Hz in 'estimation'"`` or ``"one period (2 s) repeated
        in 'estimation'"`` (records joined by ``"; "``); ``""`` when no record is a single
        line or periodic.

    References
    ----------
    Ljung 1999, System Identification, 2nd ed., Sec. 13.2 (persistent excitation).

    Examples
    --------
    >>> under_excitation({"single_frequency": ["a"], "spectra": [
    ...     {"record": "a", "channel": "q", "f_peak": 2.0, "fundamental": 2.0}]})
    "one spectral line at 2 Hz in 'a'"
    >>> under_excitation({})
    ''
    """
    rows = {(r["record"], r["channel"]): r for r in summary.get("spectra", [])}
    words = [
        f"one spectral line at {rows[(n, 'q')]['f_peak']:.3g} Hz in '{n}'"
        for n in summary.get("single_frequency", [])
    ]
    words += [
        f"one period ({1 / rows[(n, 'q')]['fundamental']:.3g} s) repeated in '{n}'"
        for n in summary.get("periodic", [])
    ]
    return "; ".join(words)


def is_periodic(rows: pd.DataFrame) -> bool:
    """Whether one record's q and excited inputs are harmonics of one fundamental.

    Parameters
    ----------
    rows : pandas.DataFrame
        The record's rows of :func:`record_spectra` (q and every ``h_i``).

    Returns
    -------
    bool
        True if q and every input above :data:`IDLE_INPUT` of the most varied one's
        variance are harmonic and share their fundamental within 1.5 bins.
    """
    inputs = rows[rows["channel"] != "q"]["variance"]
    floor = IDLE_INPUT * (float(inputs.max()) if len(inputs) else 0.0)
    rows = rows[(rows["variance"] > 0) & ((rows["channel"] == "q") | (rows["variance"] > floor))]
    f0 = rows["fundamental"].to_numpy(dtype=float)
    if rows.empty or "q" not in set(rows["channel"]) or not np.all(np.isfinite(f0)):
        return False
    same = np.all(np.abs(f0 - f0.min()) <= 1.5 * rows["df"].to_numpy(dtype=float))
    return bool(rows["harmonic"].all() and same)


def periodic_warning(spectra: pd.DataFrame, name: str) -> str:
    """Word the warning for a periodic record (:func:`is_periodic`).

    Parameters
    ----------
    spectra : pandas.DataFrame
        Rows of :func:`record_spectra`.
    name : str
        The record.

    Returns
    -------
    str
    """
    rows = spectra[(spectra["record"] == name) & (spectra["channel"] == "q")]
    f0 = float(rows["fundamental"].iloc[0])
    return (
        f"record '{name}': its inputs and q repeat one period ({1 / f0:.3g} s: all their power "
        f"is in harmonics of {f0:.3g} Hz): the data show one periodic orbit, which cannot "
        "separate stiffness from mass and damping; excite with a multisine, a chirp or "
        "band-limited noise"
    )


def record_spectra(records, kind, nperseg, power_fraction, line_bins) -> pd.DataFrame:
    """Spectral lines of q and every ``h(v_i)`` of each record (:func:`channel_lines`).

    Parameters
    ----------
    records : sequence of Record
        Records with ``name``, ``dt`` [s], ``q`` and ``v``.
    kind : {"v2", "v"}
        The input map ``h``.
    nperseg, power_fraction, line_bins
        As :func:`channel_lines`.

    Returns
    -------
    pandas.DataFrame
        One row per record and channel: ``record``, ``channel`` and the summary.
    """
    rows = []
    for r in records:
        fs = 1.0 / float(r.dt)
        hv = input_map(np.asarray(r.v, dtype=float).reshape(len(r.q), -1), kind)
        channels = {"q": r.q} | {f"h{j + 1}": hv[:, j] for j in range(hv.shape[1])}
        for name, x in channels.items():
            summary = channel_lines(x, fs, nperseg, power_fraction, line_bins)
            rows.append({"record": r.name, "channel": name, **summary})
    return pd.DataFrame(rows)
