"""The staircase identification profile of the virtual rig (debist.rig.profiles)."""

import itertools

import numpy as np
import pytest

from debist.core.errors import WorkflowError
from debist.rig.profiles import make_profile, staircase_profile

UNIT = np.sqrt([0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0])  # levels: v^2 in equal steps


@pytest.fixture(scope="module")
def stair():
    return staircase_profile()


def _sl(exc, start, stop):
    return slice(round(start / exc.hold), round(stop / exc.hold))


def test_grid_segments_and_pulses(stair):
    assert stair.name == "staircase"
    assert stair.t.size == 75000 and stair.duration == pytest.approx(75.0)
    edges = [(a, b) for _, a, b in stair.segments]
    assert edges[0][0] == 0.0 and edges[-1][1] == pytest.approx(75.0)
    for (_, b), (a, _) in itertools.pairwise(edges):
        assert a == pytest.approx(b, abs=1e-12)
    assert stair.switch_sides == (1, 2, 1, 2, 1, 2, 1)
    np.testing.assert_allclose(stair.switch_times, 8.7 + 10.0 * np.arange(7), atol=1e-9)
    pulses = [s for s in stair.segments if s[0].startswith("pulse")]
    heights = []
    for (label, a, b), side in zip(pulses, stair.switch_sides, strict=True):
        assert label == f"pulse-DE{side}" and b - a == pytest.approx(0.8)
        on, off = (stair.r1, stair.r2) if side == 1 else (stair.r2, stair.r1)
        sl = _sl(stair, a, b)
        assert np.ptp(on[sl]) == 0.0 and np.all(off[sl] == 0.0)  # rectangular, one DE
        heights.append(on[sl][0])
    np.testing.assert_allclose(heights, [3000, 2400, 2100, 3000, 2400, 2100, 3000])
    assert [s[0] for s in stair.segments].count("staircase") == 8  # 7 blocks + a truncated one


def test_blocks_step_one_voltage_at_a_time_on_the_level_grid(stair):
    side = 1  # the beam starts in the left well: DE 1 pushes towards the barrier
    seen = {1: set(), 2: set()}  # (towards, deeper) level pairs per well
    for label, a, b in stair.segments:
        if label.startswith("pulse"):
            side = 3 - side
        if label != "staircase":
            continue
        sl = _sl(stair, a, b)
        r = (stair.r1[sl], stair.r2[sl])
        towards, deeper = r if side == 1 else r[::-1]
        held = np.stack([towards[::1000], deeper[::1000]], axis=1)  # one sample per 1 s level
        # every level is held for its whole second
        np.testing.assert_array_equal(np.repeat(held, 1000, axis=0)[: towards.size, 0], towards)
        i = np.array([np.argmin(np.abs(UNIT * 1000.0 - x)) for x in held[:, 0]])
        j = np.array([np.argmin(np.abs(UNIT * 3000.0 - x)) for x in held[:, 1]])
        np.testing.assert_allclose(held[:, 0], UNIT[i] * 1000.0)  # towards: up to v_sub
        np.testing.assert_allclose(held[:, 1], UNIT[j] * 3000.0)  # deeper: up to v_deep
        changed = (np.diff(i) != 0).astype(int) + (np.diff(j) != 0).astype(int)
        assert changed.max() <= 1  # a serpentine: one voltage per step
        seen[side] |= set(zip(i.tolist(), j.tolist(), strict=True))
    # both wells walk the whole 4 x 4 grid
    assert seen[1] == seen[2] == set(itertools.product(range(4), range(4)))


def test_dither_is_seeded_and_stays_on_the_levels_it_dithers():
    a = staircase_profile(duration=20.0, dither=0.2, seed=3)
    b = staircase_profile(duration=20.0, dither=0.2, seed=3)
    c = staircase_profile(duration=20.0, dither=0.2, seed=4)
    plain = staircase_profile(duration=20.0)
    np.testing.assert_array_equal(a.r1, b.r1)
    assert not np.array_equal(a.r1, c.r1)
    sl = _sl(a, 0.5, 8.5)  # the first block, left well: DE 1 towards, DE 2 deeper
    np.testing.assert_array_equal(a.r1[sl] == 0.0, plain.r1[sl] == 0.0)  # zero levels stay 0
    assert a.r1[sl].max() <= 1000.0 and a.r2[sl].max() <= 3000.0
    dev = (a.r1 - plain.r1)[sl]
    assert 0.0 < np.abs(dev).max() <= 0.2 * 1000.0 + 1e-9
    np.testing.assert_array_equal(staircase_profile(duration=20.0, seed=9).r1, plain.r1)


def test_options_and_the_workflow_route():
    short = make_profile("staircase", duration=37.5, v_sub=1200.0, seed=2)
    assert short.switch_sides == (1, 2, 1) and short.r1.size == 37500
    assert short.r1[short.r2 == 0.0].max() == 3000.0  # the pulses
    deep = staircase_profile(duration=20.0, v_deep=2000.0)
    # the first block walks the deeper DE's two lowest levels
    assert deep.r2[500:8500].max() == pytest.approx(2000.0 * np.sqrt(1.0 / 3.0))
    one_row = staircase_profile(duration=20.0, rows=1, step=0.5)
    assert one_row.segments[1] == ("staircase", 0.5, 2.5)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duration": 9.0}, "shorter than one staircase episode"),
        ({"v_deep": 3500.0}, r"v_deep.*<= `v_max`"),
        ({"step": 0.0005}, "not a multiple"),
        ({"rows": 5}, "rows"),
        ({"rows": True}, "rows"),
        ({"dither": 0.6}, "dither"),
        ({"v_sub": 3000.0}, r"v_sub.*below"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        staircase_profile(**kwargs)
    with pytest.raises(WorkflowError) as err:
        make_profile("staircase", **kwargs)
    assert "'staircase'" in str(err.value)
