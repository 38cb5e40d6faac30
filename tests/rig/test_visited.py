"""Where a rig experiment can inform each curve (debist.rig.visited), on logs built by hand."""

import numpy as np
import pytest

from debist.rig.visited import excitation_blocks, rest_points, visited_intervals

A = 10e-3  # [m] well position of the cubic restoring force


def test_rest_points_of_a_cubic_are_its_stable_and_unstable_zeros():
    """f = k q (q^2 - A^2) has stable zeros at +-A and the unstable one at 0, here on grid
    points (exactly)."""
    q = np.linspace(-20e-3, 20e-3, 401)
    wells, barrier = rest_points(q, 3e4 * q * (q**2 - A**2))
    assert wells == pytest.approx([-A, A], abs=1e-12)
    assert barrier == pytest.approx(0.0, abs=1e-12)


def test_rest_points_of_an_offset_cubic_interpolate_between_grid_points():
    """A zero between grid points, by linear interpolation: the barrier of f = k q (q^2 - A^2)
    + F_0 moves to about -F_0 / k*(0) = F_0 / (k A^2)."""
    q = np.linspace(-20e-3, 20e-3, 4001)
    k, F_0 = 3e4, 1e-4
    _, barrier = rest_points(q, k * q * (q**2 - A**2) + F_0)
    assert barrier == pytest.approx(F_0 / (k * A**2), rel=1e-3)


def test_rest_points_reject_a_monostable_curve():
    q = np.linspace(-1.0, 1.0, 11)
    with pytest.raises(ValueError) as err:
        rest_points(q, q)
    assert "unstable" in str(err.value) and "zero" in str(err.value)


def test_excitation_blocks_skip_pulses_and_rest():
    t = np.arange(0.0, 10.0, 0.5)
    segments = [("rest", 0.0, 2.0), ("noise", 2.0, 4.0), ("pulse1", 4.0, 5.0), ("chirp", 5.0, 7.0)]
    block = excitation_blocks(segments, t)
    assert t[block].tolist() == [2.0, 2.5, 3.0, 3.5, 5.0, 5.5, 6.0, 6.5]


def _log(seed: int = 7):
    """Two dwells: at -A with input 1 on, then at +A with it on at half the level, each
    +-0.5 mm of uniform scatter, and a fast transit between them with the input on."""
    rng = np.random.default_rng(seed)
    n = 1000
    q = np.concatenate([-A + rng.uniform(-5e-4, 5e-4, n), np.linspace(-A, A, 50),
                        A + rng.uniform(-5e-4, 5e-4, n)])  # fmt: skip
    q_dot = np.concatenate([np.full(n, 1e-4), np.full(50, 1.0), np.full(n, 1e-4)])
    h = np.concatenate([np.full(n, 4.0), np.full(50, 9.0), np.full(n, 1.0)])
    return q, h, q_dot


def test_visited_intervals_are_the_percentiles_of_the_applied_dwell_positions():
    """Independent computation: the 1st and 99th percentile of each dwell's positions; the
    transit (fast) is not a dwell, and its larger input does not set the threshold's
    reference because it lies outside the blocks."""
    q, h, q_dot = _log()
    block = np.ones(q.size, dtype=bool)
    block[1000:1050] = False  # the transit is a pulse
    got = visited_intervals(q, h, block, q_dot, [-A, A], 0.0)
    want = [tuple(np.percentile(q[:1000], [1, 99])), tuple(np.percentile(q[1050:], [1, 99]))]
    assert np.array(got) == pytest.approx(np.array(want), abs=1e-15)
    assert got[0][1] - got[0][0] == pytest.approx(0.98e-3, rel=0.05)  # of the 1 mm scatter


def test_visited_intervals_leave_out_a_well_where_the_input_was_off():
    """At +A the input is at a quarter of its block maximum: below active = 0.3, no interval."""
    q, h, q_dot = _log()
    block = np.ones(q.size, dtype=bool)
    block[1000:1050] = False
    got = visited_intervals(q, h, block, q_dot, [-A, A], 0.0, active=0.3)
    assert len(got) == 1 and got[0][1] < 0


def test_visited_intervals_need_min_samples_and_one_value_per_sample():
    q, h, q_dot = _log()
    block = np.zeros(q.size, dtype=bool)
    block[:10] = True  # 10 dwell samples at -A only
    assert visited_intervals(q, h, block, q_dot, [-A, A], 0.0, min_samples=20) == []
    assert len(visited_intervals(q, h, block, q_dot, [-A, A], 0.0, min_samples=10)) == 1
    with pytest.raises(ValueError) as err:
        visited_intervals(q[:-1], h, block, q_dot, [-A, A], 0.0)
    assert "value" in str(err.value) and "sample" in str(err.value)
