"""Configuration of the identification stage (the ``[identify]`` workflow section)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.config import config_from_section
from pipeline.errors import WorkflowError
from pipeline.identify.terms import INPUT_MAPS, check_terms


@dataclass(frozen=True)
class IdentifyConfig:
    """Hyper-parameters of the RBF identification (Masoud & Maas 2025, Sec. 4.2).

    Parameters
    ----------
    M : int
        Number of RBF centres per curve (paper: 10).
    sigma_n : float
        Normalised width, sigma = sigma_n * delta_xi (paper: 0.5).
    rbf : tuple of str
        RBF-weighted curves, a subset of ("c", "d", "g").
    backbone : tuple of str
        Physical backbone terms identified in the same least squares: any of
        "linear_spring", "cubic_spring", "viscous", "coulomb", "offset",
        "input_gain", and with a ``[physics]`` section the analytical model's curves
        "physics_spring", "physics_damping", "physics_gain" (scaled; see
        :class:`pipeline.identify.terms.PhysicsPrior`). With "clip" evaluation the
        model outside the estimation range is the backbone plus the RBF curves held at
        their edge values.
    input_map : {"v2", "v"}
        h(v) = v^2 (DE actuators, default) or v (rigs whose force is linear in v).
    outside : {"clip", "zero"}
        RBF evaluation outside the estimation range.
    T_z : float or "search"
        Friction time constant [s]; ``"search"`` runs the bounded outer search,
        0 fixes z = q_dot.
    T_z_bounds : tuple of float or None
        Search interval [s]; default [dt, 100 dt] of the estimation data.
    m_q : float or "identify"
        Generalised mass [kg]; 1 identifies the curves per unit mass. With
        "identify", ``input_gain`` must fix the input gains instead. In a workflow,
        ``"physics"`` takes the analytical model's ``m_q`` at ``q = 0`` (the identify
        stage resolves it from ``[physics]``).
    input_gain : tuple of float or None
        Known gains g_0,i [N/V or N/V^2] when ``m_q = "identify"``.
    coulomb_velocity : float
        v_c of the smoothed Coulomb term tanh(z/v_c) [unit of q / s].
    trim : int
        Samples dropped at each end of each estimation record (edge effects of
        the derivatives).
    lowpass : float or None
        Corner frequency [Hz] of a zero-phase low-pass (4th-order Butterworth, applied
        forwards and backwards) on both sides of Eq. 40 per record: the filtered
        equation error. The model is linear in its parameters, so filtering every
        regressor column and the output keeps the parameters; it only weights the
        frequency band where the one-coordinate model holds. ``None``: no filter.
        Below the Nyquist frequency of every record.
    q_range : tuple of float or None
        Operating range of Eq. 39 [unit of q]; default the estimation data range.
    max_condition : float
        Largest accepted condition number of the column-scaled regressor.
    min_support : int
        Fewest samples within one width of every centre.
    published : dict
        Published parameter values to print next to the identified ones.
    refine : dict, bool or None
        ``[identify.refine]``: refine the least-squares parameters by minimising the
        windowed free-run error on the estimation data (see
        :class:`pipeline.identify.refine.RefineConfig`); absent or false: no refinement.
    prior : PhysicsPrior or None
        The analytical model's curves for the ``physics_*`` terms; set by the identify
        stage from the workflow's ``[physics]`` section, not a workflow key.
    """

    M: int = 10
    sigma_n: float = 0.5
    rbf: tuple[str, ...] = ("c", "d", "g")
    backbone: tuple[str, ...] = ("linear_spring", "cubic_spring", "viscous")
    input_map: str = "v2"
    outside: str = "clip"
    T_z: float | str = "search"
    T_z_bounds: tuple[float, float] | None = None
    m_q: float | str = 1.0
    input_gain: tuple[float, ...] | None = None
    coulomb_velocity: float = 1e-3
    trim: int = 0
    lowpass: float | None = None
    q_range: tuple[float, float] | None = None
    max_condition: float = 1e8
    min_support: int = 10
    published: dict[str, float] | None = None
    refine: dict[str, Any] | bool | None = None
    prior: Any = None

    @classmethod
    def from_dict(cls, section: dict[str, Any]) -> IdentifyConfig:
        """Build and validate the configuration from a workflow section.

        Parameters
        ----------
        section : dict
            The ``[identify]`` table.

        Returns
        -------
        IdentifyConfig

        Raises
        ------
        WorkflowError
            On an unknown key or an invalid value, naming it.
        """
        kw = dict(section)
        if "prior" in kw:
            raise WorkflowError(
                "[identify]: unknown key 'prior' (the analytical backbone comes from [physics])"
            )
        for key in ("rbf", "backbone", "T_z_bounds", "input_gain", "q_range"):
            if isinstance(kw.get(key), list):
                kw[key] = tuple(kw[key])
        cfg = config_from_section(cls, kw, "[identify]")
        cfg._check()
        return cfg

    def _check(self) -> None:
        check_terms(self.rbf, self.backbone)
        if self.input_map not in INPUT_MAPS:
            raise WorkflowError(
                f"[identify] input_map must be one of {INPUT_MAPS}, got {self.input_map!r}"
            )
        if not (self.T_z == "search" or (isinstance(self.T_z, int | float) and self.T_z >= 0)):
            raise WorkflowError(
                f"[identify] T_z must be 'search' or a time >= 0 [s], got {self.T_z!r}"
            )
        if self.T_z_bounds is not None and not (0 < self.T_z_bounds[0] < self.T_z_bounds[1]):
            raise WorkflowError(
                f"[identify] T_z_bounds must satisfy 0 < lo < hi, got {self.T_z_bounds}"
            )
        if self.m_q == "identify":
            gains = {"input_gain", "physics_gain"} & set(self.backbone)
            if self.input_gain is None or "g" in self.rbf or gains:
                raise WorkflowError(
                    "[identify] m_q = 'identify' needs fixed `input_gain` values and no 'g' or "
                    "'input_gain' term (one scale must be known)"
                )
        elif not (isinstance(self.m_q, int | float) and self.m_q > 0):
            raise WorkflowError(
                f"[identify] m_q must be a mass > 0 [kg] or 'identify', got {self.m_q!r}"
            )
        elif "g" not in self.rbf and not {"input_gain", "physics_gain"} & set(self.backbone):
            raise WorkflowError(
                "[identify] the model needs an input term: 'g' in rbf or 'input_gain'"
            )
        if self.trim < 0:
            raise WorkflowError(f"[identify] trim must be >= 0 samples, got {self.trim!r}")
        if self.lowpass is not None and not (
            isinstance(self.lowpass, int | float) and self.lowpass > 0
        ):
            raise WorkflowError(
                f"[identify] lowpass must be a frequency > 0 [Hz], got {self.lowpass!r}"
            )
        if self.refine:
            from pipeline.identify.refine import refine_config

            refine_config(self.refine)
        if not self.coulomb_velocity > 0:
            raise WorkflowError(
                f"[identify] coulomb_velocity must be > 0, got {self.coulomb_velocity!r}"
            )
