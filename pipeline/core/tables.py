"""Helpers on canonical rig-log tables shared by the stages: input columns, sample time."""

from __future__ import annotations

import lazy_loader as lazy
import numpy as np

from debist.core.errors import RigLogError

# the libraries below load on first use (lazy_loader): start-up of the CLI
pd = lazy.load("pandas")

__all__ = ["UNIFORM_TOL", "input_columns", "sample_time"]

#: Largest relative deviation of a time step from the median accepted as uniform sampling.
UNIFORM_TOL = 0.05


def input_columns(frame: pd.DataFrame) -> list[str]:
    """Input channel names v1..vN of a canonical rig-log table, in order."""
    names, k = [], 1
    while f"v{k}" in frame.columns:
        names.append(f"v{k}")
        k += 1
    return names


def sample_time(frame: pd.DataFrame, name: str) -> float:
    """Uniform sample time of a table [s].

    Parameters
    ----------
    frame : pandas.DataFrame
        Table with a ``t`` column [s].
    name : str
        Table name for messages.

    Returns
    -------
    float
        Median time step [s].

    Raises
    ------
    RigLogError
        If a step deviates from the median by more than :data:`UNIFORM_TOL`.
    """
    steps = np.diff(frame["t"].to_numpy())
    dt = float(np.median(steps))
    worst = int(np.argmax(np.abs(steps - dt)))
    if abs(steps[worst] - dt) > UNIFORM_TOL * dt:
        raise RigLogError(
            f"non-uniform sampling in data set '{name}': step {steps[worst]:.6g} s at "
            f"t = {frame['t'].iloc[worst]:.6g} s against the median {dt:.6g} s; "
            "set [ingest] resample = {{ sample_time = ... }}",
            path=frame.attrs.get("source"),
            channel="t",
        )
    return dt
