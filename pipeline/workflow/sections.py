"""The ``[validate]``, ``[study]`` and ``[report]`` tables.

Their domain code (:mod:`debist.validate`, :mod:`debist.studies`, :mod:`debist.report.html`)
loads the simulator, the whole identification or the page templates; the configuration
classes live here, so that checking a workflow loads none of them. Both are built by
:meth:`debist.core.config.SectionConfig.from_dict`.

References
----------
Masoud & Maas 2025, Sec. 5 (free-run validation, Eq. 41) and Fig. 11 (the studies).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, TypeVar

import pydantic
from pydantic import BeforeValidator, Field, FiniteFloat, NonNegativeInt, PositiveFloat, PositiveInt
from typing_extensions import TypedDict

from debist.core.config import (
    CONFIG,
    AsTuple,
    ConfigValueError,
    SectionConfig,
)
from debist.core.units import lookup_unit

__all__ = ["PublishedResult", "ReportConfig", "StudyConfig", "ValidateConfig"]


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
        largest |q| of the estimation range (:func:`default_q_limit`).
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
        MATLAB's ``simsd``; :func:`debist.validate.replicate_spread`): the spread of NRMSE(q)
        they give and the share that lose the motion; at most as many as the identify stage
        drew (``[identify] bootstrap``); 0: none.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :meth:`from_dict` raises a ``WorkflowError`` naming the key instead).
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
