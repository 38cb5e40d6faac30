"""A plant zoo: seeded virtual DE rigs that no workflow of this repository was tuned on.

Each member is a prototype of the Eq. 37 family on the virtual rig, drawn from a seed and
its index (``numpy.random.default_rng([seed, index, attempt])``, so a member does not depend on
the zoo's size): the full plant of Sec. 3 or the reduced one of Eq. 24-26 (alternating with
the index); a friction law (generalised Maxwell slip with 1-5 elements, Coulomb and viscous,
or viscous only); DE asymmetry (gains ``k_1``, ``k_2`` within +-15 %, anchor offsets, a
sensor zero shift of up to +-0.5 mm, a constant tip force); modal mass +-30 %; damping
x0.5-2; HV drivers with 1-10 ms lag and a slew limit; a laser logged as the trailing mean of
1-10 samples, with lag, noise and quantisation; an estimation record and two unseen records
of several excitation profiles and lengths. :func:`draw_member` returns the member's rig as
plain workflow sections; :func:`member_ok` checks it statically (bistable with its tip
force, switched by either DE at 3 kV) before anything is simulated.

References
----------
Masoud & Maas 2025, Sec. 3 (plant), Eq. 24-26 and 37 (reduced model), Sec. 5.1 (rig);
Al-Bender, Lampaert & Swevers 2005 (generalised Maxwell-slip friction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from debist.physics.params import V_MAX, PrototypeParams
from debist.physics.statics import equilibria, switching_voltage
from debist.rig.params import RigParams

__all__ = [
    "ESTIMATION_PROFILES",
    "UNSEEN_PROFILES",
    "ZOO_VERSION",
    "ZooMember",
    "draw_member",
    "member_ok",
    "sub_threshold",
]

#: Version of the drawing rules: a zoo folder records it, and a member drawn by other rules
#: is not mixed into it.
ZOO_VERSION = 1
#: Profiles an estimation record is drawn from: the paper's switch sequence (rectangular or
#: ramped pulses), staircases, random steps, sine sweeps.
ESTIMATION_PROFILES = ("identification", "ramps", "staircase", "steps", "sweep")
#: Profiles of the unseen records (the validation profile's chirps and multisines too).
UNSEEN_PROFILES = ("identification", "ramps", "staircase", "steps", "sweep", "validation")
#: Friction laws and their draw probabilities.
FRICTION_LAWS = {"maxwell-slip": 0.6, "coulomb+viscous": 0.2, "viscous": 0.2}
#: Sub-threshold excitation as a fraction of the member's lowest switching threshold.
SUB_MARGIN = 0.65


@dataclass(frozen=True)
class ZooMember:
    """One zoo member: its rig as workflow sections, the record roles and what was drawn.

    Attributes
    ----------
    name : str
        ``m<index>`` (three digits).
    seed, index, attempt : int
        The draw (``attempt`` counts the draws rejected before it).
    rig : dict
        A ``[rig]`` section (:class:`debist.rig.config.RigConfig`): ``sample_time`` [s],
        ``prototype`` (deviations from the paper's prototype, SI), ``plant``
        (:class:`~debist.rig.params.RigParams` keys, SI) and ``experiments``.
    roles : dict of str to str
        Experiment name -> ``"estimation"`` or ``"validation"``.
    traits : dict
        What distinguishes the member, for tables: plant, friction law, slip elements,
        logger averaging, sample time, profiles.
    """

    name: str
    seed: int
    index: int
    attempt: int
    rig: dict[str, Any]
    roles: dict[str, str]
    traits: dict[str, Any] = field(default_factory=dict)

    def rig_params(self) -> RigParams:
        """Return the member's :class:`RigParams` (prototype included)."""
        proto = PrototypeParams.paper().replace(**self.rig["prototype"])
        return RigParams.from_dict({**self.rig["plant"], "prototype": proto})


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _friction(rng: np.random.Generator) -> tuple[str, dict[str, Any]]:
    """Draw a friction law and its parameters (SI) as ``[rig.plant]`` keys."""
    laws = list(FRICTION_LAWS)
    law = laws[int(rng.choice(len(laws), p=list(FRICTION_LAWS.values())))]
    if law == "maxwell-slip":
        n = int(rng.integers(1, 6))
        breakaway = _log_uniform(rng, 1e-3, 4e-3)  # [N]
        share = rng.dirichlet(np.ones(n))
        delta = np.sort([_log_uniform(rng, 5e-6, 300e-6) for _ in range(n)])  # [m]
        F = breakaway * share
        return law, {"friction_F": F.tolist(), "friction_k": (F / delta).tolist(),
                     "friction_c": 0.0}  # fmt: skip
    if law == "coulomb+viscous":  # one element with 2 um pre-sliding: a regularised Coulomb law
        F = _log_uniform(rng, 1e-3, 3e-3)
        return law, {"friction_F": [F], "friction_k": [F / 2e-6],
                     "friction_c": _log_uniform(rng, 0.02, 0.2)}  # fmt: skip
    return law, {"friction_F": [], "friction_k": [], "friction_c": _log_uniform(rng, 0.05, 0.3)}


def _experiment(rng: np.random.Generator, profile: str, duration: float) -> dict[str, Any]:
    """One ``[rig.experiments.<name>]`` table (the sub-threshold level is set later)."""
    exp: dict[str, Any] = {
        "profile": "identification" if profile == "ramps" else profile,
        "duration": duration,
        "seed": int(rng.integers(0, 2**31 - 1)),
        "profile_seed": int(rng.integers(0, 2**31 - 1)),
        "format": str(rng.choice(["5", "7.3"])),
    }
    if profile == "ramps":
        exp["ramps"] = [0.0, float(np.round(rng.uniform(0.3, 1.5), 2))]
    return exp


def draw_member(seed: int, index: int, attempt: int = 0) -> ZooMember:
    """Draw one zoo member's rig (not yet checked: see :func:`member_ok`).

    Parameters
    ----------
    seed : int
        The zoo's seed (>= 0).
    index : int
        The member's index (>= 0); even indices are full plants, odd ones reduced.
    attempt : int
        How many draws of this member were rejected before (>= 0).

    Returns
    -------
    ZooMember
        Its rig sections, record roles and traits; ``v_sub`` of the experiments still
        unset (:func:`sub_threshold`).

    Raises
    ------
    ValueError
        For a negative seed, index or attempt.

    References
    ----------
    Masoud & Maas 2025, Table 1 (the nominal prototype the draws scatter around).
    """
    if min(seed, index, attempt) < 0:
        raise ValueError(f"seed, index and attempt must be >= 0, got {seed}, {index}, {attempt}")
    rng = np.random.default_rng([seed, index, attempt])
    plant = "full" if index % 2 == 0 else "reduced"
    p0 = PrototypeParams.paper()
    damping = _log_uniform(rng, 0.5, 2.0)
    prototype = {
        "b": p0.b + float(rng.normal(0.0, 0.3e-3)),
        "dz_1": float(rng.normal(0.0, 0.2e-3)),
        "dz_2": float(rng.normal(0.0, 0.2e-3)),
        "m": p0.m * float(rng.uniform(0.7, 1.3)),
        "eta": p0.eta * damping,
        "eta_v": p0.eta_v * damping,
    }
    law, friction = _friction(rng)
    sample_time = float(rng.choice([5e-3, 10e-3]))
    noise = _log_uniform(rng, 0.3e-6, 3e-6)  # [m]; the quantiser below it (dithered)
    average = int(rng.integers(1, 11))
    plant_keys = {
        "model": plant,
        **friction,
        "gain_1": float(rng.uniform(0.85, 1.15)),
        "gain_2": float(rng.uniform(0.85, 1.15)),
        "force_offset": float(rng.uniform(-2e-3, 2e-3)),
        "sensor_offset": float(rng.uniform(-0.5e-3, 0.5e-3)),
        "driver_tau": float(rng.uniform(1e-3, 10e-3)),
        "driver_slew": _log_uniform(rng, 50e3, 300e3),
        "sensor_average": average,
        "sensor_lag": float(rng.choice([0.0, rng.uniform(0.2e-3, 2e-3)])),
        "sensor_noise": noise,
        "sensor_resolution": noise * float(rng.uniform(0.05, 0.5)),
        "monitor_noise": float(rng.uniform(1.0, 5.0)),
        "oversample": 10,
    }
    est_profile = str(rng.choice(ESTIMATION_PROFILES))
    others = [p for p in UNSEEN_PROFILES if p != est_profile]
    unseen = [str(p) for p in rng.choice(others, size=2, replace=False)]
    experiments = {"estimation": _experiment(rng, est_profile, _duration(rng, est_profile, 30, 60))}
    for i, prof in enumerate(unseen, start=1):
        experiments[f"unseen_{i}"] = _experiment(rng, prof, _duration(rng, prof, 20, 40))
    roles = {"estimation": "estimation", "unseen_1": "validation", "unseen_2": "validation"}
    traits = {
        "plant": plant,
        "friction": law,
        "slip_elements": len(friction["friction_k"]) if law == "maxwell-slip" else 0,
        "sensor_average": average,
        "sample_time": sample_time,
        "estimation_profile": est_profile,
        "unseen_profiles": unseen,
    }
    rig = {"sample_time": sample_time, "prototype": prototype, "plant": plant_keys,
           "experiments": experiments}  # fmt: skip
    return ZooMember(f"m{index:03d}", seed, index, attempt, rig, roles, traits)


def _duration(rng: np.random.Generator, profile: str, lo: float, hi: float) -> float:
    """Draw a record length [s] in ``[lo, hi]`` on a 0.5 s grid (staircases: at least 40 s)."""
    if profile == "staircase":
        lo = max(lo, 40.0)
        hi = max(hi, lo)
    return float(np.round(rng.uniform(lo, hi) * 2.0) / 2.0)


def member_ok(rig: RigParams, v_switch: float = 0.95 * V_MAX) -> bool:
    """Whether a member works as the paper's actuator, with its tip force and DE gains.

    Bistable at 0 V with the tip force ``F_0`` plus or minus twice the friction's breakaway
    force (and at least 0.5 mN), and switched by ``v_switch`` on either DE alone (each DE's
    force scaled by its gain: ``sqrt(gain_i) v_switch`` on the prototype). Static, on the full
    model's equilibria (Eq. 15), which the reduced plant shares at 0 V.

    Parameters
    ----------
    rig : RigParams
        The member's rig.
    v_switch : float
        Voltage that must switch it [V]; default 95 % of 3 kV.

    Returns
    -------
    bool
        True if both wells hold and both DEs switch.

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Sec. 3.3.3-3.3.4.
    """
    p, F0 = rig.prototype, rig.force_offset
    margin = max(2.0 * rig.breakaway_force, 0.5e-3)
    if not any(e.stable and e.q < 0 for e in equilibria(p, F=F0 + margin)):
        return False
    if not any(e.stable and e.q > 0 for e in equilibria(p, F=F0 - margin)):
        return False
    for de, gain in ((1, rig.gain_1), (2, rig.gain_2)):
        stable = [e for e in equilibria(p, F=F0, **{f"v{de}": math.sqrt(gain) * v_switch})
                  if e.stable]  # fmt: skip
        if not stable or not all((e.q > 0) if de == 1 else (e.q < 0) for e in stable):
            return False
    return True


def sub_threshold(rig: RigParams) -> float:
    """Return the member's sub-threshold excitation level [V].

    :data:`SUB_MARGIN` times the lower of the two DEs' static switching thresholds with the
    member's tip force, each in applied volts (the prototype's threshold over
    ``sqrt(gain_i)``), at most the profiles' default 1 kV.

    Parameters
    ----------
    rig : RigParams
        The member's rig.

    Returns
    -------
    float
        ``v_sub`` [V].

    References
    ----------
    Masoud & Maas 2025, Eq. 15, Sec. 3.3.4 (switching threshold).
    """
    levels = [
        switching_voltage(rig.prototype, de, tol=10.0, F=rig.force_offset,
                          v_max=V_MAX * math.sqrt(gain)) / math.sqrt(gain)
        for de, gain in ((1, rig.gain_1), (2, rig.gain_2))
    ]  # fmt: skip
    return float(min(1000.0, SUB_MARGIN * min(levels)))
