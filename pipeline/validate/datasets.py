"""Validation data sets built from the stages' tables (what every free run is scored on).

Shared by the validate, compare and study stages and by :mod:`debist.stages.studies`, so that
no stage imports another stage.
"""

from __future__ import annotations

from debist.core.tables import input_columns
from debist.validate.freerun import DataSet

__all__ = ["validation_datasets"]


def validation_datasets(tables, derivs) -> list[DataSet]:
    """Assemble the measured data of every table for free-run validation.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical rig-log tables (``t [s], q, v1..vN``; ``attrs["role"]``,
        ``attrs["units"]``).
    derivs : mapping of str to pandas.DataFrame
        Their derivatives (``q_dot``, ``q_ddot``).

    Returns
    -------
    list of DataSet
        One per table, in table order.

    References
    ----------
    Masoud & Maas 2025, Sec. 5 (validation on every data set).
    """
    out = []
    for name, frame in tables.items():
        d = derivs[name]
        out.append(
            DataSet(
                name=name,
                role=frame.attrs.get("role", "validation"),
                t=frame["t"].to_numpy(),
                q=frame["q"].to_numpy(),
                q_dot=d["q_dot"].to_numpy(),
                q_ddot=d["q_ddot"].to_numpy(),
                v=frame[input_columns(frame)].to_numpy(),
                q_unit=frame.attrs.get("units", {}).get("q", "m"),
            )
        )
    return out
