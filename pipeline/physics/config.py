"""The ``[analyze]`` table: which design analyses of Section 3 to run, and on what grid.

The configuration class only, apart from :mod:`debist.physics.analysis` that runs it, so that
checking a workflow does not load the statics, the dynamics and the reduced model.

References
----------
Masoud & Maas 2025, Section 3, Fig. 3-7.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

import pydantic
from pydantic import Field, PositiveFloat

from debist.core.config import (
    CONFIG,
    ConfigValueError,
    Interval,
    SectionConfig,
)

__all__ = ["MAX_DEGREE", "AnalyzeConfig"]

#: Highest degree of the reduced model's polynomials: one less than the 401 points of the
#: static path they are fitted to (:func:`debist.physics.reduced.fit_reduced`).
MAX_DEGREE = 400


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class AnalyzeConfig(SectionConfig):
    """Settings of the design analysis (the workflow's ``[analyze]`` section).

    Parameters
    ----------
    b_range : tuple of float
        Range of the pre-strain sweep (Fig. 3) [m]; default ``[b_max - 12.5 mm, b_max]``
        (``None``). The paper plots [20, 30] mm; the default extends it so that both
        bifurcation points (``z_b,min``, ``z_b,max``) fall inside.
    n_b : int
        Screw positions in the sweep, ``>= 2``.
    q_max : float
        Half width of the force-displacement and capacitance curves (Fig. 4, 5) [m].
    n_q : int
        Points of those curves, ``>= 2``.
    t_end : float
        Duration of the full vs reduced simulation (Fig. 7) [s].
    left, right : tuple of float
        On/off times of the 3 kV steps on DE 1 and DE 2 in that simulation [s].
    degree : int
        Polynomial degree of ``q_m(q)`` of the reduced model (Eq. 24), ``2 <= degree <=``
        :data:`MAX_DEGREE`: the least squares fits 401 points of the static path
        (:func:`debist.physics.reduced.fit_reduced`), so a higher degree is not determined.

    Raises
    ------
    pydantic.ValidationError
        On a range that is empty or not increasing, a non-positive count or duration, a
        step after ``t_end`` or a value of the wrong type (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key).

    References
    ----------
    Masoud & Maas 2025, Fig. 3-7.
    """

    SECTION: ClassVar[str] = "[analyze]"

    b_range: Interval | None = None
    n_b: Annotated[int, Field(ge=2)] = 101
    q_max: PositiveFloat = 15e-3
    n_q: Annotated[int, Field(ge=2)] = 121
    t_end: PositiveFloat = 5.0
    left: Interval = (0.5, 1.5)
    right: Interval = (2.5, 3.5)
    degree: Annotated[int, Field(ge=2, le=MAX_DEGREE)] = 30

    def __post_init__(self) -> None:
        if self.right[1] > self.t_end:
            raise ConfigValueError(
                "right", f"steps that end by t_end = {self.t_end} [s]", list(self.right)
            )
