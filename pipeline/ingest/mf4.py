"""Reader of ASAM MDF measurement files (MF4, also MDF 3), with the optional asammdf.

An MDF file holds channel groups; each group has a master channel (its time base, usually
``time`` in ``s``) and data channels sampled on it. The reader maps that onto the same
:class:`~debist.ingest.raw.RawLog` as a dSPACE recording: one raster (time base) per
channel group, every data channel tied to its group's raster, named by its MDF channel
name and carrying its MDF unit. Channels are then selected by ``name`` or ``regex`` like
ControlDesk block paths; a ``unit`` omitted in the ingest spec is the channel's own unit.
Channels of one group share a time base; channels of several groups need ``resample``.
Channels whose samples are not a vector (arrays, structures) are left out.

asammdf is an optional dependency: ``pip install debist[mf4]``.

References
----------
ASAM e.V., "ASAM MDF", version 4.1.1 (2019), the measurement data format; D. Hrisca,
asammdf (https://asammdf.readthedocs.io), the reader used here.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from debist.core.errors import RigLogError
from debist.ingest.raw import RawChannel, RawLog

__all__ = ["read_mf4"]

_INSTALL = "reading MF4 files needs the optional package asammdf: pip install debist[mf4]"


def _open(path: Path):
    try:
        from asammdf import MDF
    except ImportError:
        raise RigLogError(_INSTALL, path=path) from None
    try:
        return MDF(path)
    except Exception as exc:  # asammdf raises many kinds on a damaged file
        raise RigLogError(f"cannot read MF4 file ({type(exc).__name__}: {exc})", path=path) from exc


def read_mf4(path: Path) -> RawLog:
    """Read every channel group of an MDF file.

    Parameters
    ----------
    path : Path
        An MF4 (or MDF 3) file.

    Returns
    -------
    RawLog
        Format ``"mf4"``; ``rasters``: one time base per channel group, named by its
        master channel (``"time"``; ``"time (group 2)"`` when several groups share that
        name) with the master's unit; ``channels``: the data channels in file order, each
        with its unit (``""`` when none) and the index of its group's raster.

    Raises
    ------
    RigLogError
        asammdf is not installed (naming ``pip install debist[mf4]``), or the file is not
        a readable MDF file.
    """
    mdf = _open(path)
    try:
        groups = []
        for g, group in enumerate(mdf.groups):
            master = mdf.masters_db.get(g)
            if len(group.channels) <= (0 if master is None else 1):
                continue
            groups.append((g, group, master))
        masters = [
            (group.channels[m].name or "time") if m is not None else "time"
            for _, group, m in groups
        ]
        repeated = Counter(masters)
        rasters: list[RawChannel] = []
        channels: list[RawChannel] = []
        for k, ((g, group, master), name) in enumerate(zip(groups, masters, strict=True)):
            unit = group.channels[master].unit if master is not None else "s"
            label = name if repeated[name] == 1 else f"{name} (group {g})"
            rasters.append(RawChannel(label, np.asarray(mdf.get_master(g)), unit or "s", k))
            for i in range(len(group.channels)):
                if i == master:
                    continue
                signal = mdf.get(group=g, index=i)
                samples = np.asarray(signal.samples)
                if samples.ndim != 1 or samples.dtype.names is not None:
                    continue
                channels.append(RawChannel(signal.name, samples, signal.unit or "", k))
    except RigLogError:
        raise
    except Exception as exc:
        raise RigLogError(f"cannot read MF4 file ({type(exc).__name__}: {exc})", path=path) from exc
    finally:
        mdf.close()
    if not channels:
        raise RigLogError("the MF4 file holds no data channel", path=path)
    return RawLog(path, "mf4", tuple(channels), rasters=tuple(rasters))
