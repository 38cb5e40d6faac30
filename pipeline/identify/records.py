"""Identification records built from the stages' tables (the rows of Eq. 40).

Shared by the identify, compare and study stages and by :mod:`debist.stages.studies`: a small
module they import, so that no stage imports another stage.

References
----------
Masoud & Maas 2025, Eq. 40.
"""

from __future__ import annotations

from debist.core.errors import WorkflowError
from debist.core.tables import input_columns
from debist.identify.fit import Record

__all__ = ["estimation_records"]


def estimation_records(tables, derivs) -> list[Record]:
    """Build the identification records of Eq. 40 from the estimation tables.

    Parameters
    ----------
    tables : mapping of str to pandas.DataFrame
        Canonical rig-log tables (``t [s], q, v1..vN``); ``attrs["role"]`` marks the
        estimation data.
    derivs : mapping of str to pandas.DataFrame
        Their derivatives (``q_dot``, ``q_ddot``; ``attrs["dt"]`` the sample time [s]).

    Returns
    -------
    list of Record
        One record per estimation table, in table order.

    Raises
    ------
    WorkflowError
        If no table has the role ``"estimation"``.
    """
    records = []
    for name, frame in tables.items():
        if frame.attrs.get("role") != "estimation":
            continue
        d = derivs[name]
        v = frame[input_columns(frame)].to_numpy()
        records.append(
            Record(
                name,
                frame["q"].to_numpy(),
                d["q_dot"].to_numpy(),
                d["q_ddot"].to_numpy(),
                v,
                float(d.attrs["dt"]),
            )
        )
    if not records:
        raise WorkflowError("no estimation data set: mark one with role = 'estimation'")
    return records
