"""The raw content of a rig log as the readers return it, before channel mapping.

Every reader (:mod:`~debist.ingest.mat`, :mod:`~debist.ingest.text`,
:mod:`~debist.ingest.parquet`, :mod:`~debist.ingest.mf4`) returns a :class:`RawLog`;
:mod:`~debist.ingest.channels` maps it to the canonical table. Nothing here touches a file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["RawChannel", "RawLog"]


@dataclass(frozen=True)
class RawChannel:
    """One recorded channel, as stored in the file.

    Parameters
    ----------
    name : str
        Channel name: MAT variable name, dSPACE block path ``Y(i).Name``, CSV header or
        Parquet column name; ``"column <i>"`` for a headerless text file.
    data : ndarray, shape (n_samples,)
        The values, any dtype (numeric conversion and checks happen in channels.py).
    unit : str or None
        The unit the file declares for the channel (dSPACE ``Unit``, Parquet field
        metadata ``unit``, MF4 channel unit); None or ``""`` when it declares none.
    raster : int or None
        dSPACE and MF4 recordings: index into :attr:`RawLog.rasters` of the channel's time base.
    """

    name: str
    data: np.ndarray
    unit: str | None = None
    raster: int | None = None


@dataclass(frozen=True)
class RawLog:
    """Everything a reader found in a rig log.

    Parameters
    ----------
    path : Path
        The file.
    format : str
        ``"mat-v5"``, ``"mat-v7.3"``, ``"csv"``, ``"parquet"`` or ``"mf4"``.
    channels : tuple of RawChannel
        The channels in file order (``column = i`` selects ``channels[i]`` when
        :attr:`by_column` is true).
    rasters : tuple of RawChannel
        dSPACE recordings: the time bases ``X(1..k)``, named by their raster name; MF4
        files: the master channel of each channel group; empty for other files.
    by_column : bool
        Whether channels may be selected by 0-based column index (text, Parquet).
    has_names : bool
        False for a headerless text file (channels are only addressable by column).
    variables : tuple of RawChannel
        MAT files: every numeric top-level variable as stored (vector or n x k matrix in
        MATLAB orientation, samples in rows), selectable with ``var`` (and ``column``);
        empty for other files.
    """

    path: Path
    format: str
    channels: tuple[RawChannel, ...]
    rasters: tuple[RawChannel, ...] = ()
    by_column: bool = False
    has_names: bool = True
    variables: tuple[RawChannel, ...] = ()

    @property
    def names(self) -> list[str]:
        """Names of the channels, in file order."""
        return [c.name for c in self.channels]
