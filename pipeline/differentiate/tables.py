"""q_dot and q_ddot of canonical rig-log tables by one differentiator (TVRegDiff by default).

The differentiate stage's computation (:mod:`debist.stages.differentiate` is its adapter);
the sensitivity studies call it too.

References
----------
Masoud & Maas 2025, Sec. 4 (the derivatives of Eq. 40); R. Chartrand, Numerical
differentiation of noisy, nonsmooth data, ISRN Applied Mathematics (2011).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import lazy_loader as lazy

from debist.core import progress
from debist.core.errors import ConvergenceWarning, PlausibilityWarning, RigLogError, WorkflowError
from debist.core.tables import sample_time
from debist.differentiate.base import differentiate

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["differentiate_tables"]


def _check_cutoff(cutoff_hz: float | None, dt: float, name: str, source: str | None) -> None:
    """Warn when a low-pass cutoff [Hz] is at or above the record's Nyquist frequency."""
    nyquist = 0.5 / dt
    if cutoff_hz is None or cutoff_hz < nyquist:
        return
    where = f"file '{source}', " if source else ""
    warnings.warn(
        f"{where}data set '{name}': [differentiate] cutoff_hz = {cutoff_hz:g} Hz is not below "
        f"the Nyquist frequency {nyquist:.6g} Hz of its samples (dt = {dt:.6g} s), so the "
        f"low-pass removes nothing; set it below {nyquist:.6g} Hz to smooth the derivatives",
        PlausibilityWarning,
        stacklevel=3,
    )


def differentiate_tables(
    tables: Mapping[str, pd.DataFrame], section: Mapping[str, Any]
) -> dict[str, pd.DataFrame]:
    """Differentiate q of every table twice (TVRegDiff by default).

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical rig-log tables.
    section : mapping
        The ``[differentiate]`` section: ``method`` plus that method's parameters.

    Returns
    -------
    dict of str to pandas.DataFrame
        Per table: ``t [s], q, q_hat, q_dot [unit/s], q_ddot [unit/s^2]``.

    Raises
    ------
    WorkflowError
        For an unknown method or parameter.
    RigLogError
        For non-uniform sampling, or a record the method's settings do not suit (fewer
        samples than a Savitzky-Golay window), naming the file and the data set.

    Warns
    -----
    PlausibilityWarning
        When ``cutoff_hz`` (``method = "spectral"``) is not below a record's Nyquist
        frequency ``1 / (2 dt)`` (Shannon 1949): the low-pass then removes nothing.
    """
    params = dict(section)
    method = params.pop("method", "tvregdiff")
    out = {}
    for i, name in enumerate(tables):
        progress.report("differentiate: data sets", i, len(tables))
        frame = tables[name]
        dt = sample_time(frame, name)
        q = frame["q"].to_numpy()
        with warnings.catch_warnings():
            # Stopping at the configured iteration count is recorded as data (attrs).
            warnings.simplefilter("ignore", ConvergenceWarning)
            try:
                res = differentiate(q, dt, method=method, params=params)
            except (WorkflowError, RigLogError):
                raise
            except ValueError as exc:  # the record does not suit the method's settings
                raise RigLogError(
                    f"data set '{name}' ({q.size} samples): [differentiate] method = "
                    f"{method!r}: {exc}",
                    path=frame.attrs.get("source"),
                ) from None
        _check_cutoff(res.info.get("cutoff_hz"), dt, name, frame.attrs.get("source"))
        deriv = pd.DataFrame(
            {
                "t": frame["t"].to_numpy(),
                "q": q,
                "q_hat": res.x_hat,
                "q_dot": res.x_dot,
                "q_ddot": res.x_ddot,
            }
        )
        deriv.attrs.update({"method": method, "converged": bool(res.converged), "dt": dt})
        if "check" in res.info:  # stopped at its limit: how far a longer run moved them
            deriv.attrs["longer_run"] = res.info["check"]
        if "alpha_search" in res.info:  # alpha = "auto": what it chose, and from what
            deriv.attrs["alpha"] = res.info["alpha"]
            deriv.attrs["alpha_search"] = res.info["alpha_search"]
        out[name] = deriv
    progress.report("differentiate: data sets", len(tables), len(tables))
    return out
