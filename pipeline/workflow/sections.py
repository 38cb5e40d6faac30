"""The ``[study]`` and ``[report]`` tables.

Their code (:mod:`debist.stages.studies`, :mod:`debist.report.html`) loads the whole
identification or the page templates; the configuration classes live here, so that checking
a workflow loads none of them (the ``[validate]`` table is :mod:`debist.validate.config`).
Both are built by
:meth:`debist.core.config.SectionConfig.from_dict`.

References
----------
Masoud & Maas 2025, Fig. 11 (the studies).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, TypeVar

import pydantic
from pydantic import BeforeValidator, Field, PositiveFloat

from debist.core.config import (
    CONFIG,
    SectionConfig,
)

__all__ = ["ReportConfig", "StudyConfig"]


def _as_list(value: object) -> object:
    """Let a study grid be one number or an array (TOML arrays are lists)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (value,)
    return tuple(value) if isinstance(value, list) else value


_T = TypeVar("_T")


#: A study grid: one value or a non-empty array of values.
_Grid = Annotated[tuple[_T, ...], BeforeValidator(_as_list), Field(min_length=1)]


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class StudyConfig(SectionConfig):
    """The ``[study]`` workflow section: grids of the hyper-parameter studies.

    Parameters
    ----------
    M : sequence of int
        Numbers of RBF centres per curve (Fig. 11b), each ``>= 2``.
    sigma_n : sequence of float
        Normalised widths ``sigma = sigma_n * delta_xi`` (Fig. 11b), each ``> 0``.
    alpha : sequence of float
        TVRegDiff regularisation weights of the first derivative (Fig. 11c), each
        ``> 0``, in the units of the data: ``alpha`` scales with the unit of q
        (q in m needs 1e-3 times the value for q in mm, see
        :class:`~debist.differentiate.tvregdiff_method.TVRegDiffConfig`). The defaults span the
        project's default ``1e-5`` for q in metres (the paper's 0.01 for mm)
        by two decades below and one above.
    free_run : bool
        True: score every model by the free-run NRMSE(q) (Eq. 41) on the
        estimation data (and the validation data). False: equation-error MSE
        only, much faster.
    max_samples : int
        At most this many samples (the first ones) of each record are fitted
        and simulated, ``>= 100``.

    Raises
    ------
    pydantic.ValidationError
        If a list is empty or a value has the wrong type or is out of range (a
        ``ValueError``; :meth:`from_dict` raises a ``WorkflowError`` naming the key).

    Examples
    --------
    >>> StudyConfig.from_dict({"M": [4, 8], "free_run": False}).M
    (4, 8)
    """

    SECTION: ClassVar[str] = "[study]"

    M: _Grid[Annotated[int, Field(ge=2)]] = (4, 6, 8, 10, 12, 16)
    sigma_n: _Grid[PositiveFloat] = (0.25, 0.5, 0.75, 1.0, 1.5)
    alpha: _Grid[PositiveFloat] = (1e-7, 1e-6, 1e-5, 1e-4)
    free_run: bool = True
    max_samples: Annotated[int, Field(ge=100)] = 20000


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class ReportConfig(SectionConfig):
    """The ``[report]`` workflow section (an empty table takes the defaults).

    Parameters
    ----------
    zoom_window : float
        Length of the zoom on the most dynamic part of each free run (Fig. 13): the window
        of this length whose acceleration ``q_ddot`` has the largest RMS [s].

    Raises
    ------
    pydantic.ValidationError
        On a non-positive or non-numeric value (:meth:`from_dict` raises a
        ``WorkflowError`` naming the key instead).

    References
    ----------
    Masoud & Maas 2025, Fig. 13.
    """

    SECTION: ClassVar[str] = "[report]"

    zoom_window: PositiveFloat = 2.0
