"""Configuration of the identification stage (the ``[identify]`` workflow section)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields, replace
from typing import Annotated, Any, ClassVar, Literal

import pydantic
from pydantic import Field, FiniteFloat, NonNegativeInt, PositiveFloat, PositiveInt

from debist.core.config import (
    CONFIG,
    AsTuple,
    ConfigValueError,
    Interval,
    SectionConfig,
    config_from_section,
    dotted_key,
)
from debist.core.errors import WorkflowError
from debist.identify.regularise import CONSTRAINT
from debist.model.terms import check_terms

#: Workflow-facing description of ``T_z`` (its type is a union).
_T_Z = 'a time >= 0 [s] or "search"'
#: Workflow-facing description of ``creep`` (its type is a union).
_CREEP = 'false, a relaxation rate > 0 [1/s] or "search"'
#: Workflow-facing description of ``slip`` (its type is a union).
_SLIP = "false, a number of elements >= 1, or their break-away deflections > 0 [unit of q]"
#: The default grid of break-away deflections, as fractions of the estimation range of q:
#: geometric from 1.5e-4 to 1e-2 (for a +-16 mm range, 4.8 um to 0.32 mm).
SLIP_GRID = (1.5e-4, 1e-2)
#: Workflow-facing description of ``m_q``; ``"physics"`` is resolved by the identify stage.
_M_Q = 'a mass > 0 [kg], "identify", or "physics" (with a [physics] section)'


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class IdentifyConfig(SectionConfig):
    """Hyper-parameters of the RBF identification (Masoud & Maas 2025, Sec. 4.2).

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type, is out of range or the terms do not make a model
        (a ``ValueError``; :meth:`from_dict` raises a ``WorkflowError`` naming the key).

    Notes
    -----
    Each field is one key of the ``[identify]`` workflow section, documented under its
    declaration and in the workflow key reference. Why the settings are what they are:
    docs/explanation/settings.md and docs/explanation/terms.md.

    References
    ----------
    Masoud & Maas 2025, Sec. 4.2, Eq. 37-40; Al-Bender, Lampaert & Swevers 2005, IEEE Trans.
    Autom. Control 50(11) (generalised Maxwell slip).
    """

    SECTION: ClassVar[str] = "[identify]"
    INTERNAL: ClassVar[tuple[str, ...]] = ("prior",)

    M: Annotated[int, Field(ge=2)] = 10
    """Number of RBF centres per curve (paper: 10)."""
    sigma_n: PositiveFloat = 0.5
    """Normalised RBF width, sigma = sigma_n * delta_xi (paper: 0.5)."""
    rbf: Annotated[tuple[str, ...], AsTuple] = ("c", "d", "g")
    """RBF-weighted curves, a subset of ("c", "d", "g", "gh"); "gh" is the input force's second
    order in h(v_i), g_h,i(q) h(v_i)^2.
    """
    backbone: Annotated[tuple[str, ...], AsTuple] = ("linear_spring", "cubic_spring", "viscous")
    """Physical backbone terms of the same least squares (:data:`debist.model.terms.TERMS`; the
    ``physics_*`` terms need a ``[physics]`` section).
    """
    input_map: Literal["v2", "v"] = "v2"
    """h(v) = v^2 (DE actuators, default) or v (rigs whose force is linear in v)."""
    outside: Literal["clip", "zero"] = "clip"
    """RBF evaluation outside the estimation range: held at the edge values or zero."""
    T_z: Annotated[Annotated[float, Field(ge=0)] | Literal["search"], Field(description=_T_Z)] = (
        "search"
    )
    """Friction time constant [s]; "search" runs a bounded search, 0 fixes z = q_dot."""
    T_z_bounds: Annotated[
        tuple[PositiveFloat, PositiveFloat] | None,
        AsTuple,
        Field(description="[lo, hi] [s] with 0 < lo < hi"),
    ] = None
    """Search interval of T_z [s]; default [dt, 100 dt] of the estimation data."""
    creep: Annotated[
        Literal[False] | PositiveFloat | Literal["search"], Field(description=_CREEP)
    ] = False
    """Maxwell creep of the DEs (Eq. 26) as identified force terms: a relaxation rate [1/s],
    "search", or false (Eq. 37 without creep).
    """
    creep_bounds: Annotated[
        tuple[PositiveFloat, PositiveFloat] | None,
        AsTuple,
        Field(description="[lo, hi] [1/s] with 0 < lo < hi"),
    ] = None
    """Search interval of the creep rate [1/s]; default [1 / longest record, 1 / (10 dt)]."""
    slip: Annotated[
        Literal[False] | Annotated[int, Field(ge=1, le=20)] | tuple[PositiveFloat, ...],
        AsTuple,
        Field(description=_SLIP),
    ] = False
    """Generalised Maxwell-slip friction elements: a number N (placed on :data:`SLIP_GRID`) or
    their break-away deflections [unit of q]; false: Eq. 37's friction only.
    """
    inertia: Annotated[
        Annotated[int, Field(ge=0, le=4)] | tuple[Annotated[int, Field(ge=1, le=4)], ...],
        AsTuple,
        Field(description="a degree 0..4 of m(q) in q, or a list of powers 1..4"),
    ] = 0
    """Position-dependent inertia m(q) = m_q + sum_a mu_a q^a: a degree or a list of powers; 0: the
    constant m_q of Eq. 37.
    """
    m_q: Annotated[PositiveFloat | Literal["identify"], Field(description=_M_Q)] = 1.0
    """Generalised mass [kg]; 1 identifies per unit mass; "identify" needs ``input_gain``;
    "physics" takes the analytical model's m_q at q = 0.
    """
    input_gain: Annotated[tuple[FiniteFloat, ...] | None, AsTuple] = None
    """Known gains g_0,i [N/V or N/V^2] when ``m_q = "identify"``."""
    coulomb_velocity: PositiveFloat = 1e-3
    """v_c of the smoothed Coulomb term tanh(z/v_c) [unit of q / s]."""
    trim: NonNegativeInt = 0
    """Samples dropped at each end of each estimation record (edge effects of the derivatives).
    """
    lowpass: Annotated[PositiveFloat | None, Field(description="a frequency > 0 [Hz]")] = None
    """Corner frequency [Hz] of a zero-phase low-pass on both sides of Eq. 40 (the filtered
    equation error); none: no filter.
    """
    weights_window: Annotated[PositiveFloat | None, Field(description="a duration > 0 [s]")] = None
    """Window [s] of the local RMS that weights a second least squares; none: ordinary least
    squares (the paper).
    """
    effective_mass: bool | None = None
    """Rescale the model so that its effective mass at the wells is m_q
    (:mod:`debist.identify.mass`); false: the curves as fitted (the paper); unset: true unless
    ``m_q = "identify"``.
    """
    q_range: Interval | None = None
    """Operating range of Eq. 39 [unit of q]; default the estimation data range."""
    max_condition: Annotated[float, Field(gt=0, allow_inf_nan=True)] = 1e8
    """Largest accepted condition number of the column-scaled regressor."""
    min_support: NonNegativeInt = 10
    """Fewest samples within one width of every centre."""
    published: dict[str, FiniteFloat] | None = None
    """Published parameter values to print next to the identified ones."""
    refine: Annotated[
        dict[str, Any] | bool | None,
        Field(description="a table of [identify.refine] settings, true or false"),
    ] = None
    """The ``[identify.refine]`` table: refine by the windowed free-run error; absent or false: no
    refinement.
    """
    auto: Annotated[
        dict[str, Any] | None,
        Field(description="a table of candidate lists, e.g. M = [6, 8, 10], and folds"),
    ] = None
    """The ``[identify.auto]`` table: candidate lists chosen by blocked cross-validation of the
    free-run error; absent: the values given are used.
    """
    smoothing: Annotated[
        Annotated[float, Field(ge=0, allow_inf_nan=False)] | Literal["gcv"],
        Field(description='a weight >= 0 or "gcv"'),
    ] = 0.0
    """Weight of a second-difference penalty on each RBF curve's weights [-]; "gcv": generalised
    cross-validation; 0: plain least squares (the paper).
    """
    tie_undriven: bool = True
    """Continue each gain g_i over the centres beyond the range its input drives (less than
    ``min_support`` samples' worth of data with v_i applied) linearly from the driven ones;
    False: their weights are free (the paper's plain least squares). The identify summary's
    ``undriven`` names them."""
    constraints: Annotated[tuple[str, ...], AsTuple] = ()
    """Sign statements on the curves, e.g. "d >= 0", imposed by bounded least squares."""
    bootstrap: NonNegativeInt = 200
    """Block-bootstrap replicates for the curves' 95 % bands; 0: no bands."""
    bootstrap_seed: NonNegativeInt = 0
    """Seed of the bootstrap's random generator."""
    band_tolerance: PositiveFloat = 0.2
    """Largest band width, a fraction of the curve's range, where a curve counts as identified."""
    model_error: bool = True
    """Add the model error calibrated on the virtual rig to the bootstrap bands; false:
    bootstrap-only bands.
    """
    prior: Any = None
    """The analytical model's curves for the ``physics_*`` terms, set by the identify stage."""

    @property
    def inertia_powers(self) -> tuple[int, ...]:
        """Powers a of q in m(q) = m_q + sum_a mu_a q^a that ``inertia`` asks for (ascending)."""
        if isinstance(self.inertia, tuple):
            return tuple(sorted(set(self.inertia)))
        return tuple(range(1, self.inertia + 1))

    @property
    def n_slip(self) -> int:
        """Number of Maxwell-slip elements ``slip`` asks for (0 without)."""
        if self.slip is False:
            return 0
        return self.slip if isinstance(self.slip, int) else len(self.slip)

    def __post_init__(self) -> None:
        for key, terms in (("rbf", (self.rbf, ())), ("backbone", ((), self.backbone))):
            try:
                check_terms(*terms)
            except WorkflowError as exc:
                raise ConfigValueError(key, message=str(exc)) from None
        bounds = self.T_z_bounds
        if bounds is not None and not bounds[0] < bounds[1]:
            raise ConfigValueError("T_z_bounds", "[lo, hi] [s] with 0 < lo < hi", list(bounds))
        bounds = self.creep_bounds
        if bounds is not None and not bounds[0] < bounds[1]:
            raise ConfigValueError("creep_bounds", "[lo, hi] [1/s] with 0 < lo < hi", list(bounds))
        gains = {"input_gain", "physics_gain"} & set(self.backbone)
        if self.effective_mass is None:  # the default: the curves on the physical mass's scale
            object.__setattr__(self, "effective_mass", self.m_q != "identify")
        if self.m_q == "identify" and self.effective_mass:
            raise ConfigValueError(
                "effective_mass",
                message="needs a known mass m_q (a number or 'physics'), not m_q = 'identify'",
            )
        if self.m_q == "identify":
            if self.input_gain is None or "g" in self.rbf or gains:
                raise ConfigValueError(
                    "m_q",
                    message="'identify' needs fixed `input_gain` values and no 'g' or "
                    "'input_gain' term (one scale must be known)",
                )
        elif "g" not in self.rbf and not gains:
            raise ConfigValueError(
                "rbf", message="the model needs an input term: 'g' in rbf or 'input_gain'"
            )

        for text in self.constraints:
            if CONSTRAINT.match(text) is None:
                raise ConfigValueError(
                    "constraints", "statements like 'd >= 0', 'g1 >= 0', 'g2 <= 0'", text
                )
        if "physics_quadratic" in self.backbone and self.input_map != "v2":
            raise ConfigValueError(
                "backbone",
                message="'physics_quadratic' is the DE force's second order in h = v^2: it needs "
                f"input_map = 'v2', not {self.input_map!r}",
            )
        if self.creep and "physics_creep" in self.backbone:
            raise ConfigValueError(
                "creep",
                message="set `creep` or the backbone term 'physics_creep', not both: a model "
                "has one creep relaxation rate (physics_creep takes Y_MW / eta_MW of [physics])",
            )
        if isinstance(self.slip, tuple) and not (
            self.slip and all(a < b for a, b in zip(self.slip, self.slip[1:], strict=False))
        ):
            raise ConfigValueError("slip", "ascending break-away deflections > 0", list(self.slip))
        if self.refine:
            refine_config(self.refine)
        if self.auto is not None:
            auto_settings(self)

    @classmethod
    def from_dict(
        cls, section: Mapping[str, Any] | None, where: str | Callable[[str], str] | None = None
    ) -> IdentifyConfig:
        """Build and validate the configuration from a workflow section.

        Parameters
        ----------
        section : dict
            The ``[identify]`` table.
        where : str or callable, optional
            The workflow table (or a function of the key giving it), for the messages
            (default ``[identify]``).

        Returns
        -------
        IdentifyConfig

        Raises
        ------
        WorkflowError
            On an unknown key (with a suggestion) or an invalid value:
            ``[identify] key: expected ..., got ...``.

        Examples
        --------
        >>> IdentifyConfig.from_dict({"M": "ten"})
        Traceback (most recent call last):
        ...
        debist.core.errors.WorkflowError: [identify] M: expected an integer, got 'ten'
        """
        if isinstance(section, Mapping) and "prior" in section:
            given = cls.SECTION if where is None else where
            label = given("prior") if callable(given) else given
            raise WorkflowError(
                f"{label} unknown key 'prior' (the analytical backbone comes from [physics])",
                key=dotted_key(label, "prior"),
                value=section["prior"],
            )
        return super().from_dict(section, where)


# ----------------------------------------------- [identify.refine] and [identify.auto]

#: Samples per restarted window of the held-out blocks' multiple-shooting score (as
#: ``[identify.refine] length``).
DEFAULT_WINDOW = 300


@pydantic.dataclasses.dataclass(frozen=True, config=CONFIG)
class RefineConfig:
    """The ``[identify.refine]`` section: the simulation-error finish of the least squares.

    Raises
    ------
    pydantic.ValidationError
        If a value has the wrong type or is out of range (a ``ValueError``;
        :func:`refine_config` raises a ``WorkflowError`` naming the key instead).

    Notes
    -----
    Each field is one key, documented under its declaration. The ridge term of ``prior`` adds
    residual rows ``prior * r_0 * sqrt(N) * (x - x_LS)`` (``r_0`` the windows' RMS error at
    ``x_LS``, ``N`` their sample count); what it does on the fleets: docs/results/fleets.md.
    """

    windows: PositiveInt = 40
    """Number of windows spread evenly over the estimation records."""
    length: Annotated[int, Field(ge=10)] = 300
    """Samples per window."""
    max_nfev: PositiveInt = 30
    """Budget of cost evaluations of the optimiser."""
    substeps: PositiveInt = 2
    """RK4 steps per sample in the window simulations."""
    interpolation: Literal["bandlimited", "linear"] = "bandlimited"
    """Input interpolation (as in validation)."""
    refine_T_z: bool = True
    """Also refine T_z (when the model has a friction lag, T_z > 0)."""
    ftol: PositiveFloat = 1e-6
    """Relative cost decrease below which the optimiser stops."""
    holdout: Annotated[int, Field(ge=0)] = 4
    """Every holdout-th block of each record is held out and judges the refinement (blocked
    cross-validation); 0: judged on the whole estimation records.
    """
    prior: float | Annotated[tuple[float, ...], AsTuple] = 0.0
    """Weight of a ridge term pulling the scaled parameters to the least-squares estimate; 0: none;
    a list: one refinement per weight, the best accepted one kept.
    """

    def __post_init__(self) -> None:
        weights = self.priors
        if not weights or min(weights) < 0:
            raise ConfigValueError(
                "prior", "a weight >= 0 or a non-empty array of them",
                list(weights) if isinstance(self.prior, tuple) else self.prior,
            )  # fmt: skip

    @property
    def priors(self) -> tuple[float, ...]:
        """The ridge weights to try, in the order given (one for a single ``prior``)."""
        return tuple(self.prior) if isinstance(self.prior, tuple) else (float(self.prior),)


def refine_config(
    section: dict | bool | None, where: str = "[identify.refine]"
) -> RefineConfig | None:
    """Parse ``[identify.refine]`` (None or ``false`` when absent: no refinement).

    Parameters
    ----------
    section : dict, bool or None
        The table, ``true`` for defaults, or nothing.
    where : str, optional
        The workflow table, for the messages.

    Returns
    -------
    RefineConfig or None

    Raises
    ------
    WorkflowError
        On an unknown key (with a suggestion) or an invalid value:
        ``[identify.refine] key: expected ..., got ...``.
    """
    if not section:
        return None
    return config_from_section(RefineConfig, {} if section is True else section, where)


#: Most candidate values of one field in a hyper-parameter grid (``[identify.auto]``): each
#: is at least one cross-validated fit, and a longer list is a slip, not a search.
MAX_GRID_VALUES = 1000


def candidate_config(base: IdentifyConfig, setting: Mapping[str, Any]) -> IdentifyConfig:
    """Return the base configuration with a candidate's values, without bootstrap.

    Parameters
    ----------
    base : IdentifyConfig
        The ``[identify]`` settings the candidates vary.
    setting : mapping
        Field name to value of one candidate of ``[identify.auto]``.

    Returns
    -------
    IdentifyConfig

    Raises
    ------
    WorkflowError
        If the candidate makes an invalid configuration (the reason named).
    """
    try:
        return replace(base, **dict(setting), bootstrap=0)
    except ValueError as exc:  # pydantic.ValidationError and ConfigValueError
        errors = getattr(exc, "errors", None)
        reason = errors()[0]["msg"] if callable(errors) and errors() else str(exc)
        raise WorkflowError(
            f"[identify] hyper-parameter grid: the setting {dict(setting)!r} is not a valid "
            f"configuration: {reason}"
        ) from None


def check_grid(base: IdentifyConfig, grid: Mapping[str, Sequence[Any]]) -> dict[str, list]:
    """Check a hyper-parameter grid: known fields, and every value a valid configuration.

    Parameters
    ----------
    base : IdentifyConfig
        The configuration the candidates vary.
    grid : mapping of str to sequence
        Candidate values per field (a single value counts as a list of one).

    Returns
    -------
    dict of str to list
        The grid with lists for values.

    Raises
    ------
    WorkflowError
        An empty grid, an unknown field, a field without values or with more than
        :data:`MAX_GRID_VALUES`, or an invalid value.
    """
    known = {f.name for f in fields(IdentifyConfig)} - {"prior", "bootstrap", "auto", "refine"}
    out = {}
    if not grid:
        raise WorkflowError("[identify] hyper-parameter grid is empty")
    for key, values in grid.items():
        if key not in known:
            raise WorkflowError(
                f"[identify] hyper-parameter grid: unknown key {key!r}; choose from {sorted(known)}"
            )
        values = list(values) if isinstance(values, list | tuple) else [values]
        if not values:
            raise WorkflowError(f"[identify] hyper-parameter grid: {key} has no values")
        if len(values) > MAX_GRID_VALUES:
            raise WorkflowError(
                f"[identify] hyper-parameter grid: {key} has {len(values)} values; at most "
                f"{MAX_GRID_VALUES} are accepted (each candidate is a cross-validated fit)"
            )
        checked = set()
        for v in values:
            if repr(v) not in checked:  # refuse an invalid value before any fit, once each
                candidate_config(base, {key: v})
                checked.add(repr(v))
        out[key] = values
    return out


def auto_settings(cfg: IdentifyConfig) -> tuple[dict[str, list], dict[str, int]]:
    """Read the ``[identify.auto]`` table of a configuration: the candidate grid and options.

    Parameters
    ----------
    cfg : IdentifyConfig
        A configuration whose ``auto`` is a table of candidate lists per field (a single
        value counts as a list of one) and optionally ``folds`` (an integer >= 2, default 4)
        and ``window`` (samples per restarted window of the score, an integer >= 10, default
        :data:`DEFAULT_WINDOW`).

    Returns
    -------
    grid : dict of str to list
        Candidates per field, each checked to make a valid configuration.
    options : dict of str to int
        ``folds`` (blocks per record) and ``window`` [samples], keyword arguments of
        :func:`select_hyperparameters`.

    Raises
    ------
    WorkflowError
        For an empty grid, an unknown field, an invalid candidate value or an invalid
        ``folds`` or ``window``, naming ``[identify.auto]``.
    """
    table = dict(cfg.auto or {})
    options = {"folds": table.pop("folds", 4), "window": table.pop("window", DEFAULT_WINDOW)}
    for key, least in (("folds", 2), ("window", 10)):
        value = options[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise WorkflowError(
                f"[identify.auto] {key}: expected an integer >= {least}, got {value!r}"
            )
    try:
        grid = check_grid(replace(cfg, auto=None), table)
    except WorkflowError as exc:
        text = str(exc).replace("[identify] hyper-parameter grid", "[identify.auto]")
        raise WorkflowError(text) from None
    return grid, options
