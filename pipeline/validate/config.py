"""The ``[validate]`` table: the settings of the free-run validation.

Its code (:mod:`debist.validate.freerun`) loads the simulator; the configuration class lives
here, apart from it, so that checking a workflow loads none of it. Built by
:meth:`debist.core.config.SectionConfig.from_dict`.

References
----------
Masoud & Maas 2025, Sec. 5 (free-run validation, Eq. 41).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import pydantic
from pydantic import FiniteFloat, NonNegativeInt, PositiveFloat, PositiveInt
from typing_extensions import TypedDict

from debist.core.config import CONFIG, AsTuple, ConfigValueError, SectionConfig
from debist.core.units import lookup_unit

__all__ = ["PublishedResult", "ValidateConfig"]


class PublishedResult(TypedDict):
    """One published result of ``[[validate.published]]``: ``{model = "...", rms = {...}}``.

    Attributes
    ----------
    model : str
        Name of the published model (with its reference).
    rms : dict of str to float
        Its RMS error per data set name [report unit].
    """

    __pydantic_config__ = CONFIG  # type: ignore[misc]

    model: str
    rms: dict[str, FiniteFloat]


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class ValidateConfig(SectionConfig):
    """The ``[validate]`` workflow section.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Notes
    -----
    Each field is one key, documented under its declaration.

    References
    ----------
    Masoud & Maas 2025, Eq. 41, Table 2; Ljung 1999, Sec. 16.6 (residual analysis).

    Examples
    --------
    >>> ValidateConfig.from_dict({"substeps": 4}).substeps
    4
    """

    SECTION: ClassVar[str] = "[validate]"

    substeps: PositiveInt = 2
    """RK4 steps per sample interval, >= 1."""
    input_interpolation: Literal["bandlimited", "linear"] = "bandlimited"
    """Input interpolation between samples."""
    init_samples: NonNegativeInt = 0
    """Samples of measured output used only to estimate the initial state, not scored; 0: start
    from the differentiated signals and score every sample.
    """
    report_unit: str | None = None
    """Unit q is reported in: the RMS column, q*, ranges and stiffness per length in the tables and
    the report, Fig. 14 and the design analysis's figures, and beside q's own unit in the export
    headers (e.g. "mV", "mm"); default mm for q in metres, else the unit of q. Stated, it is part
    of the identify and analyze stages' keys (their figures draw q in it).
    """
    q_limit: PositiveFloat | None = None
    """|q| beyond which a run counts as diverged [unit of q]; default twice the largest |q| of the
    estimation range.
    """
    published: Annotated[tuple[PublishedResult, ...], AsTuple] = ()
    """Published results to print beside ours: {model = "...", rms = {dataset = value}}."""
    analytical: bool = False
    """Also free-run the analytical reduced model (Eq. 26) of [physics] (Table 2's "analytical"
    row); needs q in metres and the two DE voltages.
    """
    engine: Literal["compiled", "numpy"] = "compiled"
    """Free-run engine: the compiled kernel or the NumPy reference (the same numbers to rounding).
    """
    predict_steps: NonNegativeInt = 10
    """Horizon k [samples] of the k-step-ahead NRMSE beside the free run; 0: no prediction scores
    and no residual analysis.
    """
    resid_lags: PositiveInt = 25
    """Largest lag [samples] of the residual analysis of the one-step prediction errors."""
    replicates: NonNegativeInt = 100
    """Bootstrap replicates of the identified model run free beside it (as MATLAB's simsd), at most
    [identify] bootstrap; 0: none.
    """

    def __post_init__(self) -> None:
        if self.report_unit is not None and lookup_unit(self.report_unit) is None:
            raise ConfigValueError(
                "report_unit", "a known unit (e.g. 'mm', 'mV')", self.report_unit
            )
