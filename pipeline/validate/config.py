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

    Parameters
    ----------
    substeps : int
        RK4 steps per sample interval, ``>= 1``.
    input_interpolation : {"bandlimited", "linear"}
        Input interpolation between samples.
    init_samples : int
        Samples of measured output a protocol allows for initialisation; the
        initial state is estimated from them only and the metrics are computed
        over the remaining samples. 0: start from the differentiated signals at
        the first sample and score every sample.
    report_unit : str or None
        Unit for the RMS column (e.g. "mV", "mm"); default the unit of q.
    q_limit : float or None
        |q| beyond which a run counts as diverged [unit of q]; default twice the
        largest |q| of the estimation range
        (:func:`~debist.validate.freerun.default_q_limit`).
    published : tuple of dict
        Published results to print beside ours: ``{model = "...", rms = {dataset = value}}``
        (:class:`PublishedResult`).
    analytical : bool
        Also free-run the analytical reduced model (Eq. 26) with the nominal parameters of
        the workflow's ``[physics]`` section (the "analytical" row of Table 2); needs ``q``
        in metres and the two DE voltages as inputs.
    engine : {"compiled", "numpy"}
        Free-run engine: the compiled kernel (:mod:`debist.simulate.kernel`, default) or the NumPy
        reference; the same scheme and the same numbers to rounding.
    predict_steps : int
        Horizon k [samples] of the k-step-ahead NRMSE scored beside the free run (each
        sample's prediction restarted from the measured state k samples earlier, as
        MATLAB's ``predict``); 0: no prediction scores and no residual analysis.
    resid_lags : int
        Largest lag [samples] of the residual analysis of the one-step prediction errors
        (autocorrelation and cross-correlation with each input, as MATLAB's ``resid``).
    replicates : int
        Bootstrap replicates of the identified model simulated in free run beside it (as
        MATLAB's ``simsd``; :func:`debist.validate.freerun.replicate_spread`): the spread of
        NRMSE(q) they give and the share that lose the motion; at most as many as the identify
        stage drew (``[identify] bootstrap``); 0: none.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).

    Examples
    --------
    >>> ValidateConfig.from_dict({"substeps": 4}).substeps
    4
    """

    SECTION: ClassVar[str] = "[validate]"

    substeps: PositiveInt = 2
    input_interpolation: Literal["bandlimited", "linear"] = "bandlimited"
    init_samples: NonNegativeInt = 0
    report_unit: str | None = None
    q_limit: PositiveFloat | None = None
    published: Annotated[tuple[PublishedResult, ...], AsTuple] = ()
    analytical: bool = False
    engine: Literal["compiled", "numpy"] = "compiled"
    predict_steps: NonNegativeInt = 10
    resid_lags: PositiveInt = 25
    replicates: NonNegativeInt = 100

    def __post_init__(self) -> None:
        if self.report_unit is not None and lookup_unit(self.report_unit) is None:
            raise ConfigValueError(
                "report_unit", "a known unit (e.g. 'mm', 'mV')", self.report_unit
            )
