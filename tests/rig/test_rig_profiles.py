"""Excitation profiles of the virtual rig (Fig. 11a identification, unseen validation)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import signal

from debist.core.errors import WorkflowError
from debist.rig.profiles import (
    PROFILES,
    V_LIMIT,
    Excitation,
    identification_profile,
    make_profile,
    validation_profile,
)

SUB_LABELS = {"noise", "chirp", "staircase", "multisine", "triangle"}


@pytest.fixture(scope="module")
def ident() -> Excitation:
    return identification_profile()


@pytest.fixture(scope="module")
def valid() -> Excitation:
    return validation_profile()


def _blocks(exc: Excitation, labels: set[str]):
    for label, start, stop in exc.segments:
        if label in labels:
            k0, k1 = round(start / exc.hold), round(stop / exc.hold)
            yield label, slice(k0, k1)


@pytest.mark.parametrize("name", ["identification", "validation"])
def test_grid_length_and_bounds(name):
    exc = make_profile(name)
    assert exc.name == name
    assert exc.hold == 1e-3
    assert exc.t.size == exc.r1.size == exc.r2.size == 37500
    assert exc.duration == pytest.approx(37.5, abs=1e-12)
    np.testing.assert_allclose(exc.t, np.arange(37500) * 1e-3, rtol=0, atol=0)
    for r in (exc.r1, exc.r2):
        assert r.min() == 0.0
        assert r.max() == 3000.0
        assert np.all(np.isfinite(r))
    # the segments tile the profile without gaps
    edges = [(a, b) for _, a, b in exc.segments]
    assert edges[0][0] == 0.0 and edges[-1][1] == pytest.approx(37.5)
    for (_, b), (a, _) in itertools.pairwise(edges):
        assert a == pytest.approx(b, abs=1e-12)
    # arrays are frozen
    with pytest.raises(ValueError) as err:
        exc.r1[0] = 1.0
    assert "-only" in str(err.value)


@pytest.mark.parametrize("builder", [identification_profile, validation_profile])
def test_same_seed_same_arrays_other_seed_differs(builder):
    a, b, c = builder(seed=5), builder(seed=5), builder(seed=6)
    np.testing.assert_array_equal(a.r1, b.r1)
    np.testing.assert_array_equal(a.r2, b.r2)
    assert a.switch_times == b.switch_times and a.segments == b.segments
    assert not np.array_equal(a.r1, c.r1) or not np.array_equal(a.r2, c.r2)


def test_identification_pulses_alternate_and_reach_v_max(ident):
    assert ident.switch_sides == (1, 2, 1, 2, 1, 2)
    np.testing.assert_allclose(ident.switch_times, [4.7, 10.5, 16.5, 22.7, 28.5, 34.5])
    pulses = [(lab, a, b) for lab, a, b in ident.segments if lab.startswith("pulse")]
    assert [lab for lab, _, _ in pulses] == ["pulse-DE1", "pulse-DE2"] * 3
    np.testing.assert_allclose([b - a for _, a, b in pulses], [0.6, 0.8, 1.0] * 2, atol=1e-9)
    for (_, a, b), side in zip(pulses, ident.switch_sides, strict=True):
        sl = slice(round(a / ident.hold), round(b / ident.hold))
        on, off = (ident.r1, ident.r2) if side == 1 else (ident.r2, ident.r1)
        assert np.all(on[sl] == 3000.0)  # rectangular
        assert np.all(off[sl] == 0.0)
    # outside the pulses both DEs stay at or below v_sub = 1 kV
    mask = np.ones(ident.t.size, bool)
    for _, a, b in pulses:
        mask[round(a / ident.hold) : round(b / ident.hold)] = False
    assert ident.r1[mask].max() == pytest.approx(1000.0)
    assert ident.r2[mask].max() == pytest.approx(1000.0)
    assert np.count_nonzero(np.maximum(ident.r1, ident.r2) > 1000.0) == 2400 + 2400


def test_ramped_identification_pulses_are_trapezoids(ident):
    """``ramps`` cycled over the pulses: 0 keeps the rectangle of Fig. 11a, a ramp time r
    gives a trapezoid (linear rise over r, flat, linear fall), 2 r longer; a cycle that no
    longer fits is dropped (here the sixth: 0.5 + 5 cycles of 5.2 s + pulses 3.2 + 4 s)."""
    np.testing.assert_array_equal(identification_profile(ramps=[0.0]).r1, ident.r1)
    exc = identification_profile(ramps=(0.0, 0.0, 1.0, 1.0))
    assert exc.switch_sides == (1, 2, 1, 2, 1)
    np.testing.assert_allclose(exc.switch_times, [4.7, 10.5, 16.5, 24.7, 32.5], atol=1e-9)
    pulses = [(a, b) for lab, a, b in exc.segments if lab.startswith("pulse")]
    np.testing.assert_allclose([b - a for a, b in pulses], [0.6, 0.8, 3.0, 2.6, 0.8], atol=1e-9)
    assert exc.segments[-1][0] == "noise"  # the 3.2 s left over: noise in the right well
    for k, ((a, b), side) in enumerate(zip(pulses, exc.switch_sides, strict=True)):
        k0, k1 = round(a / exc.hold), round(b / exc.hold)
        on = (exc.r1 if side == 1 else exc.r2)[k0:k1]
        if k in (2, 3):
            tau = np.arange(k1 - k0) * exc.hold
            expected = 3000.0 * np.clip(np.minimum(tau, (b - a) - tau) / 1.0, 0.0, 1.0)
            np.testing.assert_allclose(on, expected, rtol=0, atol=1e-9)
            assert on[500] == pytest.approx(1500.0)  # half-way up the 1 s ramp
        else:
            assert np.all(on == 3000.0)


@pytest.mark.parametrize("ramps", [(), (-0.5,), (float("nan"),), ("1",), 1.0])
def test_bad_ramps(ramps):
    with pytest.raises(ValueError) as err:
        identification_profile(ramps=ramps)
    assert "ramps" in str(err.value)


def test_validation_pulses_alternate_and_reach_v_max(valid):
    assert valid.switch_sides == (1, 2, 1, 2)
    np.testing.assert_allclose(valid.switch_times, [6.0, 13.2, 21.2, 28.2], atol=1e-9)
    for time, side in zip(valid.switch_times, valid.switch_sides, strict=True):
        (label, a, b) = next(s for s in valid.segments if s[1] == time)
        assert label == f"pulse-DE{side}"
        sl = slice(round(a / valid.hold), round(b / valid.hold))
        on, off = (valid.r1, valid.r2) if side == 1 else (valid.r2, valid.r1)
        assert on[sl].max() == 3000.0 and np.all(off[sl] == 0.0)
    # the trapezoid on DE 1 ramps 0 -> 3 kV in 0.2 s: 1.5 kV after 0.1 s
    assert valid.r1[6100] == pytest.approx(1500.0)
    assert valid.r1[5999] <= 900.0 and valid.r1[6000] == 0.0


def test_each_well_gets_subthreshold_excitation_on_both_des(ident):
    wells = []
    side = 1  # the beam starts in the left well
    for label, _start, _ in ident.segments:
        if label == "noise":
            wells.append("left" if side == 1 else "right")
        elif label.startswith("pulse"):
            side = 3 - side
    assert wells == ["left", "right"] * 3 + ["left"]
    for _, sl in _blocks(ident, {"noise"}):
        for r in (ident.r1[sl], ident.r2[sl]):
            assert r.std() > 50.0  # a real excitation, not a constant
            assert 0.15 < r.mean() / r.max() < 0.85  # an offset: v^2 is linear around it
    # independent streams on the two DEs
    sl = next(sl for _, sl in _blocks(ident, {"noise"}))
    assert abs(np.corrcoef(ident.r1[sl], ident.r2[sl])[0, 1]) < 0.2


def _band_fractions(x: np.ndarray, fs: float, edges) -> np.ndarray:
    f, p = signal.welch(x - x.mean(), fs=fs, nperseg=2000, detrend="constant")
    total = p[(f >= edges[0]) & (f <= edges[-1])].sum()
    return np.array([p[(f >= lo) & (f < hi)].sum() / total for lo, hi in itertools.pairwise(edges)])


def test_identification_noise_covers_half_to_twenty_hz(ident):
    edges = [0.5, 2.0, 5.0, 10.0, 20.0]
    fractions = []
    out_of_band = []
    for _, sl in _blocks(ident, {"noise"}):
        for r in (ident.r1[sl], ident.r2[sl]):
            if r.size < 2000:
                continue
            fractions.append(_band_fractions(r, 1.0 / ident.hold, edges))
            f, p = signal.welch(r - r.mean(), fs=1.0 / ident.hold, nperseg=2000)
            out_of_band.append(p[f > 40.0].sum() / p.sum())
    fractions = np.mean(fractions, axis=0)
    # flat band-limited noise: power roughly proportional to bandwidth (1.5 : 3 : 5 : 10)
    assert np.all(fractions > 0.04), fractions
    assert fractions[-1] > 0.3, fractions
    assert max(out_of_band) < 0.01


def test_validation_chirp_sweeps_its_band(valid):
    (_, sl), *_ = _blocks(valid, {"chirp"})
    r = valid.r1[sl]  # log chirp 0.5 -> 15 Hz on DE 1
    fractions = _band_fractions(r, 1.0 / valid.hold, [0.5, 2.0, 5.0, 15.0, 20.0])
    assert np.all(fractions[:3] > 0.1), fractions
    assert fractions[3] < 0.05
    assert r.max() == pytest.approx(900.0)


def test_identification_and_validation_differ(ident, valid):
    assert ident.switch_times != valid.switch_times
    assert np.abs(ident.r1 - valid.r1).mean() > 100.0
    assert {lab for lab, _, _ in valid.segments} >= {"chirp", "staircase", "multisine"}
    assert "noise" not in {lab for lab, _, _ in valid.segments}


def test_zero_order_hold_evaluation(ident):
    r1, r2 = ident.at([4.7, 4.7 + 0.5e-3, 4.6999, -1.0, 99.0])
    assert r1[0] == r1[1] == 3000.0
    assert r1[2] == 0.0  # the 0.2 s rest before the pulse
    assert r1[3] == ident.r1[0] and r1[4] == ident.r1[-1]
    assert r2[0] == 0.0


def test_other_grids_and_durations():
    exc = identification_profile(duration=20.0, hold=5e-4, v_max=2500.0)
    assert exc.t.size == 40000
    assert exc.r1.max() == 2500.0
    assert exc.switch_sides == (1, 2, 1)  # three cycles of 6.3, 6.0, 6.2 s fit in 20 s
    long = validation_profile(duration=80.0)
    assert long.switch_sides == (1, 2, 1, 2) * 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"v_max": 3000.1}, r"v_max.*<= 3000"),
        ({"v_max": -1.0}, "positive"),
        ({"v_sub": 3000.0}, r"v_sub.*below"),
        ({"hold": 0.02}, r"hold.*<= 0.01"),
        ({"duration": 37.5005}, "not a multiple"),
        ({"duration": 5.0}, "shorter than one"),
        ({"hold": float("nan")}, "finite"),
    ],
)
@pytest.mark.parametrize("builder", [identification_profile, validation_profile])
def test_bad_arguments(builder, kwargs, match):
    with pytest.raises(ValueError, match=match):
        builder(**kwargs)


def test_make_profile_registry_and_errors():
    assert set(PROFILES) == {"identification", "validation", "staircase", "steps", "sweep", "sine"}
    assert V_LIMIT == 3000.0
    with pytest.raises(WorkflowError) as err:
        make_profile("chirp")
    assert "'chirp'" in str(err.value)
    assert "identification" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        make_profile("validation", amplitude=1.0)
    assert "'amplitude'" in str(err.value)
    assert "v_max" in str(err.value)
    with pytest.raises(WorkflowError) as err:
        make_profile("identification", v_max=4000.0)
    assert "'identification'" in str(err.value)
    assert "v_max" in str(err.value)
    assert "3000" in str(err.value)


def test_excitation_validates_its_arrays():
    t = np.arange(4) * 0.01
    with pytest.raises(ValueError) as err:
        Excitation(t, np.array([0, 0, 3001.0, 0]), np.zeros(4), 0.01, "x")
    assert "3000" in str(err.value)
    with pytest.raises(ValueError) as err:
        Excitation(t + 0.001, np.zeros(4), np.zeros(4), 0.01, "x")
    assert "hold" in str(err.value)
    with pytest.raises(ValueError) as err:
        Excitation(t, np.zeros(3), np.zeros(4), 0.01, "x")
    assert "equal" in str(err.value) and "length" in str(err.value)
    with pytest.raises(ValueError) as err:
        Excitation(t, np.zeros(4), np.zeros(4), 0.01, "x", switch_times=(0.0,), switch_sides=(3,))
    assert "switch_sides" in str(err.value)


@pytest.mark.parametrize("name", ["steps", "sweep"])
def test_steps_and_sweep_stay_sub_threshold_between_alternating_pulses(name):
    e = make_profile(name, seed=4, duration=30.0, v_sub=800.0)
    assert e.r1.shape == (30000,)
    assert e.switch_sides == tuple(1 + i % 2 for i in range(len(e.switch_sides)))
    assert len(e.switch_sides) >= 3
    blocks = np.zeros(e.t.size, bool)
    for label, start, stop in e.segments:
        inside = (e.t >= start - 1e-9) & (e.t < stop - 1e-9)
        if label.startswith("pulse"):
            side = int(label[-1])
            assert np.max((e.r1, e.r2)[side - 1][inside]) == 3000.0
        elif label == name:
            blocks |= inside
    assert np.all(e.r1[blocks] <= 800.0 + 1e-9) and np.all(e.r2[blocks] <= 800.0 + 1e-9)
    assert np.all(e.r1 >= 0.0) and np.all(e.r2 >= 0.0)
    assert np.std(e.r1[blocks]) > 100.0 and np.std(e.r2[blocks]) > 100.0
    again = make_profile(name, seed=4, duration=30.0, v_sub=800.0)
    assert np.array_equal(again.r1, e.r1) and np.array_equal(again.r2, e.r2)


def test_steps_hold_levels_and_sweeps_cover_their_band():
    steps = make_profile("steps", seed=1, duration=20.0)
    block = next((a, b) for label, a, b in steps.segments if label == "steps")
    seg = steps.r1[(steps.t >= block[0]) & (steps.t < block[1])]
    changes = np.count_nonzero(np.diff(seg))
    assert 3 <= changes <= 5.0 / 0.2  # dwell times of 0.2-1.5 s in a 5 s block
    sweep = make_profile("sweep", seed=1, duration=20.0, v_sub=1000.0)
    a, b = next((a, b) for label, a, b in sweep.segments if label == "sweep")
    x = sweep.r1[(sweep.t >= a) & (sweep.t < b)] - 500.0
    crossings = np.count_nonzero(np.diff(np.sign(x)) != 0)
    # a log sweep 0.3 -> 15 Hz over 6 s has about 2 * 6 * (15 - 0.3) / ln(50) = 45 crossings
    assert 35 <= crossings <= 55
