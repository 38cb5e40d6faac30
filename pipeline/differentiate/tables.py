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

from debist.differentiate.base import differentiate
from debist.engine import progress
from debist.errors import ConvergenceWarning, RigLogError, WorkflowError
from debist.tables import sample_time

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["differentiate_tables"]


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
        if "alpha_search" in res.info:  # alpha = "auto": what it chose, and from what
            deriv.attrs["alpha"] = res.info["alpha"]
            deriv.attrs["alpha_search"] = res.info["alpha_search"]
        out[name] = deriv
    progress.report("differentiate: data sets", len(tables), len(tables))
    return out
