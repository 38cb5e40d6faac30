"""Scores of identified curves and free runs against the virtual rig's truth."""

import numpy as np
import pytest

from debist.rig.truthscore import curve_score, lost_switch, marked_near

Q = np.linspace(-10e-3, 10e-3, 21)


def test_curve_score_is_the_largest_error_where_marked_over_the_true_range():
    true = 100.0 * Q  # range 2.0 over the truth grid
    est = true + np.where(Q > 0, 0.05, 0.01)
    marked = np.abs(Q) <= 5e-3
    score = curve_score(Q, est, est - 0.02, est + 0.02, marked, Q, true)
    assert score.marked == 11
    assert score.max_error == pytest.approx(0.05 / 2.0)
    # the band (+-0.02) holds the truth where the error is 0.01 (q <= 0: 6 points), not 0.05
    assert score.coverage == pytest.approx(6 / 11)


def test_curve_score_interpolates_the_truth_and_ignores_points_off_its_grid():
    q_true = np.linspace(-5e-3, 5e-3, 101)
    true = np.sin(300.0 * q_true)
    est = np.sin(300.0 * Q)
    score = curve_score(Q, est, est, est, np.ones(Q.size, bool), q_true, true)
    assert score.marked == 11  # only |q| <= 5 mm lies on the truth's grid
    assert score.max_error < 1e-3
    none = curve_score(Q, est, est, est, np.zeros(Q.size, bool), q_true, true)
    assert none.marked == 0 and np.isnan(none.max_error) and np.isnan(none.coverage)
    with pytest.raises(ValueError) as err:
        curve_score(Q, est[:-1], est, est, np.ones(Q.size, bool), q_true, true)
    assert "shape" in str(err.value)


def test_marked_near_needs_a_marked_point_near_every_well():
    marked = (Q >= -9e-3) & (Q <= -7e-3)
    assert marked_near(Q, marked, [-8e-3], 2e-3)
    assert not marked_near(Q, marked, [-8e-3, 8e-3], 2e-3)
    assert marked_near(Q, marked | (Q[-3] == Q), [-8e-3, 8e-3], 2e-3)
    assert not marked_near(Q, np.zeros(Q.size, bool), [0.0], 1.0)


def test_lost_switch_counts_a_long_rest_in_the_wrong_well_only():
    dt = 0.01
    t = np.arange(0.0, 10.0, dt)
    q = np.where((t > 3.0) & (t < 7.0), 10e-3, -10e-3)  # one switch there and back
    late = np.where((t > 3.3) & (t < 7.3), 10e-3, -10e-3)  # 0.3 s late: not lost
    assert not lost_switch(q, late, 0.0, dt)
    never = np.full(t.size, -10e-3)  # stays left: 4 s in the wrong well
    assert lost_switch(q, never, 0.0, dt)
    diverged = late.copy()
    diverged[500:] = np.nan
    assert lost_switch(q, diverged, 0.0, dt)
    with pytest.raises(ValueError) as err:
        lost_switch(q, late, 0.0, 0.0)
    assert "dt" in str(err.value)
