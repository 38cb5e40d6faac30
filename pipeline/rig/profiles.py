"""Excitation profiles of the virtual rig: reference voltages of DE 1 (left) and DE 2 (right).

A profile is a pair of reference voltages ``r1``, ``r2`` [V] on the uniform grid of the
rig's DAC (zero-order hold, interval ``hold`` [s]): ``identification`` (Fig. 11a),
``validation`` (Fig. 15), ``staircase``, ``steps``, ``sweep`` and ``sine``. The first five
are episodes "sub-threshold block -> switching pulse -> free ring-down", the pulses
alternating between DE 1 and DE 2, from the left well. Their timing and design:
docs/reference/profiles.md.

References
----------
Masoud & Maas 2025, Sec. 5.1 (3 kV converters, 37.5 s identification experiment logged at
10 ms, start in the left well at q = -10 mm), Fig. 11a (identification profile: broad
frequency spectrum, both wells covered), Sec. 5.2 and Fig. 15 (validation on unseen data).
"""

from __future__ import annotations

import inspect
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from debist.core.errors import WorkflowError

__all__ = [
    "PROFILES",
    "V_LIMIT",
    "V_SUB",
    "Excitation",
    "identification_profile",
    "make_profile",
    "sine_profile",
    "staircase_profile",
    "steps_profile",
    "sweep_profile",
    "validation_profile",
]

#: Largest voltage the rig's high-voltage converters deliver [V] (Sec. 5.1).
V_LIMIT = 3000.0

#: Default peak of the sub-threshold excitation of every profile [V]: about 0.7 of the Table 1
#: prototype's static switching threshold (1.43 kV, Eq. 15).
V_SUB = 1000.0

#: Band of the identification profile's random excitation [Hz].
_ID_BAND = (0.5, 20.0)
#: Per noise block: peak of (r1, r2) as fractions of ``v_sub``. In the left well DE 1
#: pushes towards the barrier and DE 2 deeper into the well; in the right well the reverse.
_ID_LEVELS = ((1.0, 0.5), (1.0, 0.5), (0.5, 1.0), (0.5, 1.0), (0.8, 0.8), (0.8, 0.8))
#: Rectangular pulse lengths of the identification profile, cycled [s].
_ID_PULSES = (0.6, 0.8, 1.0)
#: Levels of the staircase profile as fractions of ``v_sub``: ``v^2`` in equal steps of
#: ``v_sub^2 / 3``, so the force ``g_i(q) v_i^2`` rises in equal steps.
_ST_LEVELS = (0.0, float(np.sqrt(1.0 / 3.0)), float(np.sqrt(2.0 / 3.0)), 1.0)
#: Heights of the staircase profile's switching pulses as fractions of ``v_max``, cycled:
#: the transits between the wells happen at three ``v_i^2``.
_ST_PULSES = (1.0, 0.8, 0.7)


@dataclass(frozen=True, eq=False)
class Excitation:
    """Reference voltages of both DEs on the DAC grid (zero-order hold).

    Sample ``k`` holds from ``t[k]`` to ``t[k] + hold``; the profile lasts ``n * hold``.
    The arrays are read-only.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times ``k * hold`` [s].
    r1, r2 : ndarray, shape (n,)
        Reference voltages of DE 1 (left) and DE 2 (right) [V], within ``[0, 3000]``.
    hold : float
        DAC interval [s].
    name : str
        Profile name (a key of :data:`PROFILES`).
    switch_times : tuple of float
        Onsets of the switching pulses [s] (grid times), for plots and integrator
        breakpoints; the pulse ends are in ``segments``.
    switch_sides : tuple of int
        The DE (1 or 2) each pulse drives: 1 moves the beam to the right well, 2 back to
        the left.
    segments : tuple of (str, float, float)
        The episodes ``(label, start, stop)`` [s] in time order, covering the profile:
        ``"rest"`` (both 0 V), ``"pulse-DE1"``, ``"pulse-DE2"``, and the sub-threshold
        blocks ``"noise"``, ``"chirp"``, ``"staircase"``, ``"multisine"``, ``"triangle"``.

    Raises
    ------
    ValueError
        Arrays not 1-D of equal length, ``t`` not ``k * hold``, non-finite values or
        voltages outside ``[0, 3000]`` V, mismatched ``switch_times`` / ``switch_sides``.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1 and Fig. 11a.
    """

    t: NDArray[np.float64]
    r1: NDArray[np.float64]
    r2: NDArray[np.float64]
    hold: float
    name: str
    switch_times: tuple[float, ...] = ()
    switch_sides: tuple[int, ...] = ()
    segments: tuple[tuple[str, float, float], ...] = ()

    def __post_init__(self) -> None:
        arrays = {}
        for key in ("t", "r1", "r2"):
            arr = np.array(getattr(self, key), dtype=np.float64)
            if arr.ndim != 1:
                raise ValueError(f"`{key}` must be 1-D, got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"`{key}` must be finite")
            arr.setflags(write=False)
            arrays[key] = arr
        n = arrays["t"].size
        if n == 0 or arrays["r1"].size != n or arrays["r2"].size != n:
            raise ValueError(
                f"`t`, `r1`, `r2` must be non-empty and of equal length, got "
                f"{n}, {arrays['r1'].size}, {arrays['r2'].size}"
            )
        hold = _positive("hold", self.hold)
        if not np.allclose(arrays["t"], np.arange(n) * hold, rtol=0.0, atol=1e-9 * max(1, n)):
            raise ValueError("`t` must be the DAC grid k * hold")
        for key in ("r1", "r2"):
            lo, hi = float(arrays[key].min()), float(arrays[key].max())
            if lo < 0.0 or hi > V_LIMIT:
                raise ValueError(f"`{key}` must be within [0, {V_LIMIT:g}] V, got [{lo}, {hi}]")
        if len(self.switch_times) != len(self.switch_sides):
            raise ValueError("`switch_times` and `switch_sides` must have equal lengths")
        if any(s not in (1, 2) for s in self.switch_sides):
            raise ValueError(f"`switch_sides` must hold 1 or 2, got {self.switch_sides}")
        for key, arr in arrays.items():
            object.__setattr__(self, key, arr)
        object.__setattr__(self, "hold", hold)
        object.__setattr__(self, "switch_times", tuple(float(x) for x in self.switch_times))
        object.__setattr__(self, "switch_sides", tuple(int(s) for s in self.switch_sides))
        object.__setattr__(self, "segments", tuple(tuple(s) for s in self.segments))

    @property
    def duration(self) -> float:
        """Length of the profile ``n * hold`` [s] (the last sample holds until then)."""
        return self.t.size * self.hold

    def at(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Evaluate the zero-order hold at arbitrary times.

        Parameters
        ----------
        t : array_like, shape (m,) or scalar
            Times [s]; before 0 the first sample, after the end the last one is held.

        Returns
        -------
        r1, r2 : ndarray, shape like ``t``
            Reference voltages [V] of the sample holding at ``t``.
        """
        k = np.searchsorted(self.t, np.asarray(t, dtype=np.float64), side="right") - 1
        k = np.clip(k, 0, self.t.size - 1)
        return self.r1[k], self.r2[k]


# ------------------------------------------------------------------------------ helpers
def _positive(key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"`{key}` must be a number, got {value!r}")
    x = float(value)
    if not (np.isfinite(x) and x > 0.0):
        raise ValueError(f"`{key}` must be positive and finite, got {value!r}")
    return x


def _ramps(ramps: Sequence[float]) -> tuple[float, ...]:
    """Check the ramp times of the switching pulses [s]: a non-empty list of times >= 0."""
    if isinstance(ramps, str) or not isinstance(ramps, Sequence) or not ramps:
        raise ValueError(f"`ramps` must be a non-empty list of times [s], got {ramps!r}")
    for x in ramps:
        if isinstance(x, bool) or not isinstance(x, int | float | np.integer | np.floating):
            raise ValueError(f"`ramps` must hold numbers [s], got {x!r}")
        if not (np.isfinite(x) and x >= 0.0):
            raise ValueError(f"`ramps` must hold times >= 0 [s], got {x!r}")
    return tuple(float(x) for x in ramps)


def _grid(duration: float, hold: float, v_max: float, v_sub: float) -> int:
    """Check the common arguments; return the number of DAC samples."""
    duration = _positive("duration", duration)
    hold = _positive("hold", hold)
    v_max = _positive("v_max", v_max)
    v_sub = _positive("v_sub", v_sub)
    if hold > 0.01:
        raise ValueError(f"`hold` must be <= 0.01 s (DAC faster than the 10 ms log), got {hold}")
    if v_max > V_LIMIT:
        raise ValueError(f"`v_max` must be <= {V_LIMIT:g} V (converter limit), got {v_max}")
    if v_sub >= v_max:
        raise ValueError(f"`v_sub` must be below `v_max` = {v_max}, got {v_sub}")
    n = round(duration / hold)
    if abs(n * hold - duration) > 1e-9 * max(1.0, duration):
        raise ValueError(f"`duration` = {duration} s is not a multiple of `hold` = {hold} s")
    return n


class _Builder:
    """Lays episodes end to end on the DAC grid, alternating the switching side."""

    def __init__(self, n: int, hold: float):
        self.hold = hold
        self.t = np.arange(n) * hold
        self.r = np.zeros((2, n))
        self.k = 0  # next free sample
        self.side = 1  # beam starts in the left well: the first pulse is on DE 1
        self.switch_times: list[float] = []
        self.switch_sides: list[int] = []
        self.segments: list[tuple[str, float, float]] = []

    @property
    def n(self) -> int:
        return self.t.size

    def samples(self, seconds: float) -> int:
        return round(seconds / self.hold)

    def fits(self, seconds: float) -> bool:
        return self.k + self.samples(seconds) <= self.n

    def add(self, label: str, seconds: float, fill: Callable | None = None) -> slice:
        """Append an episode; ``fill(tau)`` gives (r1, r2) at local times ``tau`` [s]."""
        m = min(self.samples(seconds), self.n - self.k)
        sl = slice(self.k, self.k + m)
        if fill is not None and m:
            r1, r2 = fill(np.arange(m) * self.hold)
            self.r[0, sl], self.r[1, sl] = r1, r2
        self.segments.append((label, self.k * self.hold, (self.k + m) * self.hold))
        self.k += m
        return sl

    def pulse(self, v_max: float, flat: float, ramp: float = 0.0) -> None:
        """Append a (trapezoidal) switching pulse on the current side, then swap sides."""
        side = self.side
        start = self.k * self.hold
        total = flat + 2.0 * ramp

        def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            if ramp > 0.0:
                shape = np.clip(np.minimum(tau, total - tau) / ramp, 0.0, 1.0)
            else:
                shape = np.ones_like(tau)
            v = v_max * shape
            zero = np.zeros_like(tau)
            return (v, zero) if side == 1 else (zero, v)

        self.add(f"pulse-DE{side}", total, fill)
        self.switch_times.append(start)
        self.switch_sides.append(side)
        self.side = 3 - side

    def finish(self, name: str) -> Excitation:
        if self.k < self.n:
            self.add("rest", (self.n - self.k) * self.hold)
        # Clip rounding below 0 V; the fills never exceed their peaks by construction.
        r = np.clip(self.r, 0.0, None)
        return Excitation(
            t=self.t,
            r1=r[0],
            r2=r[1],
            hold=self.hold,
            name=name,
            switch_times=tuple(self.switch_times),
            switch_sides=tuple(self.switch_sides),
            segments=tuple(self.segments),
        )


def _unit(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Scale a zero-mean signal to peak 1, then map it to [0, 1]: ``(1 + x / max|x|) / 2``."""
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    return 0.5 * (1.0 + (x / peak if peak > 0.0 else x))


def _unit_gauss(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Map zero-mean Gaussian noise to [0, 1]: ``+-3`` standard deviations, clipped beyond."""
    sigma = float(np.std(x)) if x.size else 0.0
    z = np.clip(x / (3.0 * sigma), -1.0, 1.0) if sigma > 0.0 else x
    return 0.5 * (1.0 + z)


def _triangle(tau: NDArray[np.float64], period: float) -> NDArray[np.float64]:
    """Triangle wave in [0, 1] starting at 0 [-]."""
    from scipy import signal

    return 0.5 * (1.0 + signal.sawtooth(2.0 * np.pi * tau / period - np.pi, width=0.5))


# ---------------------------------------------------------------------------- profiles
def identification_profile(
    *,
    duration: float = 37.5,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 0,
    ramps: Sequence[float] = (0.0,),
) -> Excitation:
    """Broad-band identification profile of Fig. 11a: switching both ways plus random noise.

    After 0.5 s rest, cycles of a 4 s band-limited noise block on both DEs (0.5-20 Hz, peaks
    cycling through fractions of ``v_sub``), 0.2 s rest, a ``v_max`` pulse of 0.6, 0.8 or 1.0 s
    on DE 1 and DE 2 in turn, and 1 s ring-down. Timing and design: docs/reference/profiles.md.

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least one cycle (6.3 s).
    hold : float
        DAC interval [s], at most 0.01.
    v_max : float
        Height of the switching pulses [V], at most 3000.
    v_sub : float
        Peak of the sub-threshold noise [V], below ``v_max`` and the switching threshold.
    seed : int
        Seed of :func:`numpy.random.default_rng`; the same seed gives identical arrays.
    ramps : sequence of float
        Ramp times of the switching pulses [s], >= 0, cycled over the pulses; default ``(0,)``,
        the rectangular pulses of Fig. 11a.

    Returns
    -------
    Excitation
        ``name = "identification"``; ``r1``, ``r2`` of shape ``(round(duration / hold),)`` [V].

    Raises
    ------
    ValueError
        Non-positive or non-finite arguments, ``v_max > 3000``, ``v_sub >= v_max``,
        ``hold > 0.01``, ``duration`` not a multiple of ``hold`` or shorter than a cycle,
        ``ramps`` empty or with a negative or non-finite time.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.1, Fig. 11a (identification data: 37.5 s, 3750 samples at
    10 ms, broad frequency spectrum, the whole measurement range covered).
    """
    n = _grid(duration, hold, v_max, v_sub)
    ramps = _ramps(ramps)
    b = _Builder(n, float(hold))
    lead, block, gap, ring = 0.5, 4.0, 0.2, 1.0

    def pulse(i: int) -> tuple[float, float]:
        """Flat time and ramp time of the i-th pulse [s]."""
        return _ID_PULSES[i % len(_ID_PULSES)], ramps[i % len(ramps)]

    if not b.fits(lead + block + gap + pulse(0)[0] + 2 * pulse(0)[1] + ring):
        raise ValueError(
            f"`duration` = {duration} s is shorter than one identification cycle "
            f"({lead + block + gap + pulse(0)[0] + 2 * pulse(0)[1] + ring:g} s, with `ramps` "
            f"{list(ramps)})"
        )
    rng = np.random.default_rng(seed)
    from scipy import signal

    sos = signal.butter(4, _ID_BAND, btype="bandpass", fs=1.0 / b.hold, output="sos")
    noise = signal.sosfiltfilt(sos, rng.standard_normal((2, n)), axis=1)

    def noise_block(levels: tuple[float, float], seconds: float) -> None:
        k0 = b.k

        def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            sl = slice(k0, k0 + tau.size)
            return (
                v_sub * levels[0] * _unit_gauss(noise[0, sl]),
                v_sub * levels[1] * _unit_gauss(noise[1, sl]),
            )

        b.add("noise", seconds, fill)

    b.add("rest", lead)
    i = 0
    while b.fits(block + gap + pulse(i)[0] + 2 * pulse(i)[1] + ring):
        noise_block(_ID_LEVELS[i % len(_ID_LEVELS)], block)
        b.add("rest", gap)
        b.pulse(v_max, *pulse(i))
        b.add("rest", ring)
        i += 1
    left = (b.n - b.k) * b.hold
    if left >= 1.0 - 1e-9:
        noise_block(_ID_LEVELS[i % len(_ID_LEVELS)], left)
    return b.finish("identification")


def validation_profile(
    *,
    duration: float = 37.5,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 1,
) -> Excitation:
    """Build the validation profile: chirps, staircase, multisine, triangles, ramped pulses.

    After 1 s rest, five episodes "block, pulse, rest" whose four pulses alternate DE 1, DE 2,
    DE 1, DE 2, so the beam ends in the left well; the blocks differ from the identification
    data in kind, amplitude and timing. Timing: docs/reference/profiles.md.

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least the rest and first episode (8 s).
    hold : float
        DAC interval [s], at most 0.01.
    v_max : float
        Height of the switching pulses [V], at most 3000.
    v_sub : float
        Peak of the sub-threshold blocks [V], below ``v_max``.
    seed : int
        Seed of :func:`numpy.random.default_rng` (multisine phases, staircase order).

    Returns
    -------
    Excitation
        ``name = "validation"``; ``r1``, ``r2`` of shape ``(round(duration / hold),)`` [V].

    Raises
    ------
    ValueError
        As :func:`identification_profile`.

    References
    ----------
    Masoud & Maas 2025, Sec. 5.2 and Fig. 15 (cross-validation on measurement data not
    used in the identification).
    """
    n = _grid(duration, hold, v_max, v_sub)
    b = _Builder(n, float(hold))
    rng = np.random.default_rng(seed)
    lead = 1.0
    if not b.fits(lead + 7.0):
        raise ValueError(f"`duration` = {duration} s is shorter than one validation episode (8 s)")

    def chirp(tau, f0, f1, seconds):
        from scipy import signal

        return _unit(signal.chirp(tau, f0, seconds, f1, method="logarithmic", phi=-90.0))

    def block_chirp_up(tau):
        return 0.9 * v_sub * chirp(tau, 0.5, 15.0, 5.0), 0.6 * v_sub * _triangle(tau, 2.5)

    def block_staircase(tau):
        levels = rng.permutation(np.array([0.2, 0.4, 0.6, 0.8, 1.0]))
        step = np.minimum((tau // 1.0).astype(int), levels.size - 1)
        return np.full_like(tau, 0.2 * v_sub), v_sub * levels[step]

    def block_multisine(tau):
        freqs = np.geomspace(0.3, 12.0, 8)
        out = []
        for _ in range(2):
            phases = rng.uniform(0.0, 2.0 * np.pi, freqs.size)
            x = np.sin(2.0 * np.pi * freqs[:, None] * tau[None, :] + phases[:, None]).sum(axis=0)
            out.append(0.9 * v_sub * _unit(x - x.mean()))
        return out[0], out[1]

    def block_chirp_down(tau):
        return 0.6 * v_sub * _triangle(tau, 2.5), 0.9 * v_sub * chirp(tau, 15.0, 0.5, 5.0)

    def block_triangle(tau):
        return v_sub * _triangle(tau, 2.5), np.zeros_like(tau)

    episodes = (  # label, block [s], fill, pulse (flat, ramp) [s] or None, rest after [s]
        ("chirp", 5.0, block_chirp_up, (0.6, 0.2), 1.2),
        ("staircase", 5.0, block_staircase, (0.5, 0.0), 1.5),
        ("multisine", 6.0, block_multisine, (1.0, 0.0), 1.0),
        ("chirp", 5.0, block_chirp_down, (0.7, 0.1), 1.0),
        ("triangle", 5.0, block_triangle, None, 2.4),
    )
    b.add("rest", lead)
    for i in itertools.count():
        label, seconds, fill, pulse, ring = episodes[i % len(episodes)]
        flat, ramp = pulse if pulse is not None else (0.0, 0.0)
        if not b.fits(seconds + flat + 2.0 * ramp + ring):
            break
        b.add(label, seconds, fill)
        if pulse is not None:
            b.pulse(v_max, flat, ramp)
        b.add("rest", ring)
    return b.finish("validation")


def staircase_profile(
    *,
    duration: float = 75.0,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 0,
    v_deep: float | None = None,
    step: float = 1.0,
    rows: int = 2,
    dither: float = 0.0,
) -> Excitation:
    """Staircase identification profile: held voltage levels in each well, then a switch.

    Blocks of both voltages held on a 4 x 4 serpentine of levels, each followed by a pulse
    of ``(1, 0.8, 0.7) * v_max`` (cycled): docs/reference/profiles.md.

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least ``0.5 + 4 rows step + 2`` s.
    hold : float
        DAC interval [s], at most 0.01.
    v_max : float
        Height of the highest switching pulse [V], at most 3000.
    v_sub : float
        Highest level of the DE pushing towards the barrier [V], below the switching threshold.
    seed : int
        Seed of :func:`numpy.random.default_rng` for the dither.
    v_deep : float or None
        Highest level of the DE pushing the beam deeper [V], at most ``v_max``; default ``v_max``.
    step : float
        Hold time of each level [s], a multiple of ``hold``.
    rows : int
        Rows of the 4 x 4 serpentine per block, 1 to 4 (a block lasts ``4 rows step``).
    dither : float
        Peak of a band-limited (0.5-20 Hz) dither on each non-zero level, a fraction in [0, 0.5].

    Returns
    -------
    Excitation
        ``name = "staircase"``; ``r1``, ``r2`` of shape ``(round(duration / hold),)`` [V].

    Raises
    ------
    ValueError
        As :func:`identification_profile`, or another argument out of range.

    References
    ----------
    Masoud & Maas 2025, Eq. 37, Sec. 5.1; Ljung 1999, System Identification, Sec. 13.2-13.3.
    """
    n = _grid(duration, hold, v_max, v_sub)
    v_deep = v_max if v_deep is None else _positive("v_deep", v_deep)
    if v_deep > v_max:
        raise ValueError(f"`v_deep` must be <= `v_max` = {v_max}, got {v_deep}")
    step = _positive("step", step)
    if round(step / hold) < 1 or abs(round(step / hold) * hold - step) > 1e-9 * max(1.0, step):
        raise ValueError(f"`step` = {step} s is not a multiple of `hold` = {hold} s")
    if isinstance(rows, bool) or not isinstance(rows, int | np.integer) or not 1 <= rows <= 4:
        raise ValueError(f"`rows` must be an integer in 1..4, got {rows!r}")
    dither = float(dither)
    if not 0.0 <= dither <= 0.5:
        raise ValueError(f"`dither` must be within [0, 0.5], got {dither}")
    b = _Builder(n, float(hold))
    unit = np.array(_ST_LEVELS)
    m = unit.size
    peaks = (v_sub, v_deep)  # towards the barrier, deeper
    lead, gap, flat, ring = 0.5, 0.2, 0.8, 1.0
    block = rows * m * step
    if not b.fits(lead + block + gap + flat + ring):
        raise ValueError(
            f"`duration` = {duration} s is shorter than one staircase episode "
            f"({lead + block + gap + flat + ring:g} s)"
        )
    rng = np.random.default_rng(seed)
    from scipy import signal

    sos = signal.butter(4, _ID_BAND, btype="bandpass", fs=1.0 / b.hold, output="sos")
    noise = signal.sosfiltfilt(sos, rng.standard_normal((2, n)), axis=1)
    # Per well: the serpentine walk, (towards, deeper) level indices; the barrier-side DE
    # in the inner loop first, then the deepening DE.
    walk = []
    for inner_near in (True, False):
        for outer in range(m):
            inner = range(m) if outer % 2 == 0 else range(m - 1, -1, -1)
            walk.extend((i, outer) if inner_near else (outer, i) for i in inner)
    done = {1: 0, 2: 0}  # levels walked per well (keyed by the DE pushing to the barrier)

    def staircase(seconds: float) -> None:
        near = b.side  # the DE pushing towards the barrier: the next pulse's side
        k0, per, start = b.k, b.samples(step), done[near]
        count = -(-b.samples(seconds) // per)
        path = np.array([walk[(start + j) % len(walk)] for j in range(count)])
        done[near] += count

        def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
            idx = path[np.arange(tau.size) // per]  # (n, 2): towards, deeper level index
            level = {near: idx[:, 0], 3 - near: idx[:, 1]}
            peak = {near: peaks[0], 3 - near: peaks[1]}
            out = []
            for de in (1, 2):
                x = peak[de] * unit[level[de]]
                if dither > 0.0:
                    u = 2.0 * _unit_gauss(noise[de - 1, k0 : k0 + tau.size]) - 1.0
                    x = np.where(x > 0.0, np.clip(x + dither * peak[de] * u, 0.0, peak[de]), 0.0)
                out.append(x)
            return out[0], out[1]

        b.add("staircase", seconds, fill)

    b.add("rest", lead)
    i = 0
    while b.fits(block + gap + flat + ring):
        staircase(block)
        b.add("rest", gap)
        b.pulse(v_max * _ST_PULSES[i % len(_ST_PULSES)], flat)
        b.add("rest", ring)
        i += 1
    left = (b.n - b.k) * b.hold
    if left >= 1.0 - 1e-9:
        staircase(left)
    return b.finish("staircase")


def _switching(
    b: _Builder,
    blocks: Sequence[tuple[str, float, Callable]],
    v_max: float,
    pulses: Sequence[tuple[float, float]],
    lead: float,
    ring: float,
) -> None:
    """Lay ``lead`` rest, then cycles "block, pulse, ring-down" until the record is full.

    ``blocks`` are ``(label, seconds, fill)`` and ``pulses`` ``(flat, ramp)`` [s], both
    cycled; a last block shorter than its cycle fills the remainder when it lasts >= 1 s.
    """
    b.add("rest", lead)
    for i in itertools.count():
        label, seconds, fill = blocks[i % len(blocks)]
        flat, ramp = pulses[i % len(pulses)]
        if not b.fits(seconds + flat + 2.0 * ramp + ring):
            break
        b.add(label, seconds, fill)
        b.pulse(v_max, flat, ramp)
        b.add("rest", ring)
    left = (b.n - b.k) * b.hold
    if left >= 1.0 - 1e-9:
        label, _, fill = blocks[0]
        b.add(label, left, fill)


def steps_profile(
    *,
    duration: float = 37.5,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 0,
) -> Excitation:
    """Build a random-step profile: sub-threshold voltage steps between switching pulses.

    After 0.5 s rest, cycles of a 5 s block, a ``v_max`` pulse (0.6-1.0 s flat; every third
    one ramped over 0.3 s) and 1.2 s ring-down, the pulses alternating DE 1 and DE 2. In a
    block each DE holds levels drawn uniformly from ``[0, v_sub]`` for dwell times drawn
    uniformly from 0.2-1.5 s, independently per DE (``numpy.random.default_rng(seed)``), so
    that ``g_i(q) v_i^2`` is seen at many static levels and in its step responses.

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least one cycle (8.3 s).
    hold : float
        DAC interval [s], at most 0.01.
    v_max : float
        Height of the switching pulses [V], at most 3000.
    v_sub : float
        Largest step level [V], below ``v_max`` (and below the switching threshold).
    seed : int
        Seed of the levels and dwell times.

    Returns
    -------
    Excitation
        ``name = "steps"``; blocks labelled ``"steps"``.

    Raises
    ------
    ValueError
        As :func:`identification_profile`.

    References
    ----------
    Ljung 1999, System Identification, Sec. 13.3 (random binary and multilevel inputs).
    """
    n = _grid(duration, hold, v_max, v_sub)
    b = _Builder(n, float(hold))
    rng = np.random.default_rng(seed)
    if not b.fits(0.5 + 5.0 + 1.6 + 1.2):
        raise ValueError(f"`duration` = {duration} s is shorter than one steps cycle (8.3 s)")

    def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        out = []
        for _ in range(2):
            edges = np.cumsum(rng.uniform(0.2, 1.5, size=int(tau[-1] / 0.2) + 2))
            levels = rng.uniform(0.0, v_sub, size=edges.size + 1)
            out.append(levels[np.searchsorted(edges, tau, side="right")])
        return out[0], out[1]

    pulses = ((0.6, 0.0), (0.8, 0.0), (0.7, 0.3), (1.0, 0.0), (0.6, 0.0), (0.8, 0.3))
    _switching(b, [("steps", 5.0, fill)], v_max, pulses, lead=0.5, ring=1.2)
    return b.finish("steps")


def sweep_profile(
    *,
    duration: float = 37.5,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 0,
) -> Excitation:
    """Build a sine-sweep profile: one DE swept at a time between switching pulses.

    After 0.5 s rest, cycles of a 6 s block, a rectangular ``v_max`` pulse (0.8 s) and 1 s
    ring-down, the pulses alternating DE 1 and DE 2. In a block one DE (alternating) follows
    a logarithmic sine sweep 0.3 -> 15 Hz (or down, every other block) about the offset
    ``v_sub / 2`` with amplitude ``v_sub / 2``; the other holds a level drawn uniformly from
    ``[0, 0.6 v_sub]`` (``numpy.random.default_rng(seed)``).

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least one cycle (8.3 s).
    hold : float
        DAC interval [s], at most 0.01.
    v_max : float
        Height of the switching pulses [V], at most 3000.
    v_sub : float
        Peak of the sweeps [V], below ``v_max`` (and below the switching threshold).
    seed : int
        Seed of the other DE's levels.

    Returns
    -------
    Excitation
        ``name = "sweep"``; blocks labelled ``"sweep"``.

    Raises
    ------
    ValueError
        As :func:`identification_profile`.

    References
    ----------
    Pintelon & Schoukens 2012, System Identification: A Frequency Domain Approach, 2nd ed.,
    Sec. 5.2 (swept sines).
    """
    from scipy import signal

    n = _grid(duration, hold, v_max, v_sub)
    b = _Builder(n, float(hold))
    rng = np.random.default_rng(seed)
    if not b.fits(0.5 + 6.0 + 0.8 + 1.0):
        raise ValueError(f"`duration` = {duration} s is shorter than one sweep cycle (8.3 s)")
    count = itertools.count()

    def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        i = next(count)
        f0, f1 = (0.3, 15.0) if i % 4 < 2 else (15.0, 0.3)
        span = max(float(tau[-1]), hold)
        swept = 0.5 * v_sub * (1.0 + signal.chirp(tau, f0, span, f1, method="logarithmic",
                                                  phi=-90.0))  # fmt: skip
        held = np.full_like(tau, rng.uniform(0.0, 0.6 * v_sub))
        return (swept, held) if i % 2 == 0 else (held, swept)

    _switching(b, [("sweep", 6.0, fill)], v_max, [(0.8, 0.0)], lead=0.5, ring=1.0)
    return b.finish("sweep")


def sine_profile(
    *,
    duration: float = 20.0,
    hold: float = 1e-3,
    v_max: float = 3000.0,
    v_sub: float = V_SUB,
    seed: int = 0,
    frequency: float | None = None,
    switching: bool = False,
) -> Excitation:
    """Build a single-frequency profile: one tone, inside one well or switching.

    After 0.5 s rest, DE 1 follows ``v_sub (1 - cos(2 pi f t)) / 2`` (DE 2 at 0 V), or with
    ``switching`` both DEs ``v_max (1 - cos(2 pi f t)) / 2`` in antiphase (two switches a
    period). Nothing in it is random.

    Parameters
    ----------
    duration : float
        Length [s]; a multiple of ``hold``, at least 0.5 s rest plus two periods.
    hold : float
        DAC interval [s], at most 0.01.
    v_max, v_sub : float
        Peak of the switching tone [V], at most 3000; peak of the tone inside the well [V].
    seed : int
        Ignored (a common signature).
    frequency : float or None
        Tone frequency ``f`` [Hz], below a tenth of ``1 / hold``; default 2 Hz, switching 0.5 Hz.
    switching : bool
        Antiphase tones on both DEs up to ``v_max`` instead of DE 1 below ``v_sub``.

    Returns
    -------
    Excitation
        ``name = "sine"``; one block ``"sine"``; switch times at the onsets of each half period
        in which a DE pulls (``switching``), else none.

    Raises
    ------
    ValueError
        As :func:`identification_profile`, or a frequency or duration out of range.

    References
    ----------
    Pintelon & Schoukens 2012, System Identification: A Frequency Domain Approach, 2nd ed.,
    Sec. 2.2 (a single line excites the frequency response at one frequency only).
    """
    n = _grid(duration, hold, v_max, v_sub)
    f = (0.5 if switching else 2.0) if frequency is None else float(frequency)
    if not (np.isfinite(f) and 0.0 < f < 0.1 / hold):
        raise ValueError(f"`frequency` must be in (0, {0.1 / hold:g}) Hz, got {frequency}")
    b = _Builder(n, float(hold))
    if not b.fits(0.5 + 2.0 / f):
        raise ValueError(f"`duration` = {duration} s is shorter than 0.5 s plus two periods")
    b.add("rest", 0.5)
    start = b.k * hold
    peak = v_max if switching else v_sub

    def fill(tau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        r1 = 0.5 * peak * (1.0 - np.cos(2.0 * np.pi * f * tau))
        r2 = 0.5 * peak * (1.0 + np.cos(2.0 * np.pi * f * tau)) if switching else 0.0 * tau
        return r1, r2

    b.add("sine", (b.n - b.k) * hold, fill)
    if switching:  # DE 1 pulls in the first half period (from the left well), DE 2 in the next
        half = 0.5 / f
        for k, onset in enumerate(np.arange(start, b.n * hold, half)):
            b.switch_times.append(float(np.round(onset / hold) * hold))
            b.switch_sides.append(1 + k % 2)
    return b.finish("sine")


#: Profile name -> builder; every builder takes keyword arguments only.
PROFILES: dict[str, Callable[..., Excitation]] = {
    "identification": identification_profile,
    "validation": validation_profile,
    "staircase": staircase_profile,
    "steps": steps_profile,
    "sweep": sweep_profile,
    "sine": sine_profile,
}


def make_profile(name: str, **kwargs: Any) -> Excitation:
    """Build a profile of :data:`PROFILES` by name (the workflow's way to choose one).

    Parameters
    ----------
    name : str
        A key of :data:`PROFILES`: ``"identification"``, ``"validation"``,
        ``"staircase"``, ``"steps"`` or ``"sweep"``.
    **kwargs
        Keyword arguments of the builder (``duration``, ``hold``, ``v_max``, ``v_sub``,
        ``seed``; the identification profile also ``ramps``, the staircase profile
        ``v_deep``, ``step``, ``rows``, ``dither``).

    Returns
    -------
    Excitation
        The profile.

    Raises
    ------
    WorkflowError
        Unknown profile name (the message lists the known ones), unknown keyword, or a
        value the builder rejects (the builder's message, prefixed with the profile).

    References
    ----------
    Masoud & Maas 2025, Fig. 11a (identification) and Fig. 15 (validation); Eq. 37
    (staircase).

    Examples
    --------
    >>> make_profile("identification", seed=3).r1.shape
    (37500,)
    >>> make_profile("chirp")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    debist.core.errors.WorkflowError: unknown excitation profile 'chirp'; known profiles: ...
    """
    if name not in PROFILES:
        raise WorkflowError(
            f"unknown excitation profile {name!r}; known profiles: {', '.join(PROFILES)}"
        )
    builder = PROFILES[name]
    known = list(inspect.signature(builder).parameters)
    unknown = sorted(set(kwargs) - set(known))
    if unknown:
        raise WorkflowError(
            f"excitation profile {name!r}: unknown parameter {unknown[0]!r}; "
            f"known parameters: {', '.join(known)}"
        )
    try:
        return builder(**kwargs)
    except ValueError as exc:
        raise WorkflowError(f"excitation profile {name!r}: {exc}") from exc
