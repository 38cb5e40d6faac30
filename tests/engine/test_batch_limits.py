"""A batch's workers fit the machine and the memory budget; no Ctrl-C is lost."""

from __future__ import annotations

import contextlib
import os
import signal
import warnings

import pytest

from debist.core.errors import DebistWarning
from debist.core.preflight import BUDGET_ENV
from debist.engine import batch


@pytest.fixture
def machine(monkeypatch):
    """A machine of 2 cores and a budget of 3 GB: room for 3 workers of 1 GB."""
    monkeypatch.setattr(batch, "usable_cores", lambda: 2)
    monkeypatch.setenv(BUDGET_ENV, "3")


def _capped(asked, items):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        n = batch._capped_workers(asked, items)
    return n, [str(w.message) for w in caught if issubclass(w.category, DebistWarning)]


def test_a_thousand_workers_on_two_cores_become_two_and_it_is_said_once(machine):
    n, said = _capped(1000, 40)
    assert n == 2
    assert said == ["batch: 2 worker(s) instead of 1000: as many as 2 core(s) allow"]


def test_workers_are_capped_by_the_memory_budget(machine, monkeypatch):
    monkeypatch.setattr(batch, "usable_cores", lambda: 64)
    n, said = _capped(40, 40)
    assert n == 3 == 3 * 10**9 // batch.WORKER_BYTES
    assert said == [
        "batch: 3 worker(s) instead of 40: as many as a memory budget of 3 GB for workers of "
        "1 GB allow"
    ]


def test_no_more_workers_than_workflows(machine):
    assert _capped(2, 1) == (1, ["batch: 1 worker(s) instead of 2: as many as 1 workflow(s) allow"])


def test_a_budget_below_one_worker_still_runs_one(machine, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "0.2")
    assert _capped(2, 5)[0] == 1


def test_workers_within_the_limits_are_kept_without_a_word(machine):
    assert _capped(2, 5) == (2, [])


def test_a_swallowed_ctrl_c_still_ends_the_block_with_keyboard_interrupt():
    # the inner suppress does what an event loop that catches the interrupt does
    with (
        pytest.raises(KeyboardInterrupt),
        batch.interrupt_kept(),
        contextlib.suppress(KeyboardInterrupt),
    ):
        os.kill(os.getpid(), signal.SIGINT)  # its handler runs before kill returns
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_that_becomes_another_error_is_a_keyboard_interrupt():
    with pytest.raises(KeyboardInterrupt) as info, batch.interrupt_kept():
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except KeyboardInterrupt:
            raise RuntimeError("cluster closed") from None
    assert isinstance(info.value.__cause__, RuntimeError)


def test_a_block_without_ctrl_c_runs_as_it_is():
    with batch.interrupt_kept():
        value = 1 + 1
    assert value == 2
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(ValueError, match="a data error"), batch.interrupt_kept():
        raise ValueError("a data error")
