"""A function called in a forked process now, its result collected later.

Two kinds of work use it. The runner starts a stage that only the report reads (``study``,
``analyze``) beside the stages after it, and the compiled kernels' first compilation ahead
of the first free run (:mod:`debist.engine.runner`); the compare stage fits its NARX peer
beside the SINDy search (:mod:`debist.stages.compare`). Each is independent CPU-bound work
while this process goes on, on one core each. :class:`BesideRun` calls the function in a
copy of this process (POSIX ``fork``: the data read so far are inherited, nothing is pickled
on the way in) and returns its result, or raises what it raised, when asked. The child's
warnings are issued here when it is joined (:func:`debist.core.forking.
call_recording_warnings`); its progress reports are not drawn (two processes cannot share one
terminal display). The results are those of a serial call: the same code on the same inputs,
with the BLAS thread limits of this process, which the fork inherits.

References
----------
Python documentation, :mod:`multiprocessing` ("Contexts and start methods",
``Process``, ``Pipe``) and :mod:`signal` (``pthread_sigmask``).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import signal
from collections.abc import Callable
from typing import Any

from debist.core.errors import ArtifactError, Interrupted
from debist.core.forking import (
    STOP_SIGNALS,
    call_recording_warnings,
    fork_context,
    replay_warnings,
)
from debist.core.progress import listening

__all__ = ["BesideRun"]

#: Seconds a stopped child gets to end on SIGTERM before it is killed.
STOP_GRACE = 5.0


#: Whether this (child) process was told to stop once already.
_stopping = False


def _mask(how: int) -> set:
    """Block or unblock the stop signals in this thread; return the previous mask (POSIX)."""
    return signal.pthread_sigmask(how, STOP_SIGNALS)


def _stop(signum: int, _frame: object) -> None:
    """Stop the child on SIGINT or SIGTERM: the first unwinds ``fn``, a later one exits.

    Raising :class:`~debist.core.errors.Interrupted` once lets the function's clean-up run
    (temporary folders are removed as after Ctrl-C); a second signal ends the process at once.
    """
    global _stopping
    if _stopping:
        os._exit(128 + signum)
    _stopping = True
    raise Interrupted(signum)


def _child(fn: Callable[[], Any], send, recv, niceness: int) -> None:
    """Call ``fn`` in the forked process without progress display; send (ok, value, warnings).

    The copy of the parent's receiving end that the fork made is closed first: if the parent
    is gone (stopped), the send then fails instead of waiting forever for a reader. The
    child's scheduling priority is lowered by ``niceness`` first (where it can be).

    The child starts with SIGINT and SIGTERM ignored (:func:`debist.core.forking.
    fork_context` with ``quiet``). While ``fn`` runs, the first one raises
    :class:`~debist.core.errors.Interrupted` inside ``fn`` (its clean-up runs); outside
    ``fn`` they are blocked or end the process by their default action. So a Ctrl-C of the
    terminal (which reaches every process of the group) or :meth:`BesideRun.stop` never
    prints the child's traceback, wherever the child is.
    """
    global _stopping
    try:
        _mask(signal.SIG_BLOCK)
        for signum in STOP_SIGNALS:
            signal.signal(signum, _stop)
        recv.close()
        if niceness:
            with contextlib.suppress(OSError):
                os.nice(niceness)
        try:
            _mask(signal.SIG_UNBLOCK)
            try:
                with listening(None):
                    value, caught = call_recording_warnings(fn)
            finally:
                _mask(signal.SIG_BLOCK)
            message = (True, value, caught)
        except BaseException as exc:
            _mask(signal.SIG_BLOCK)
            message = (False, exc, [])
        for signum in STOP_SIGNALS:  # from here a stop signal just ends the process
            signal.signal(signum, signal.SIG_DFL)
        if _stopping:  # stopped while fn ran, its clean-up done: end as the signal says
            signal.raise_signal(getattr(message[1], "signum", signal.SIGTERM))
        _stopping = True
        _mask(signal.SIG_UNBLOCK)
        _send(send, message)
    except BaseException:  # a stop signal: nobody waits for a result, nothing to say
        os._exit(1)


def _send(send, message: tuple) -> None:
    """Send the child's message to the parent, or an ArtifactError if it cannot be pickled."""
    try:
        send.send(message)
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        send.send((False, ArtifactError(f"the result could not be sent back: {exc}"), []))
    except OSError:  # the parent is gone: nobody to tell
        pass
    finally:
        send.close()


class BesideRun:
    """Call a function in a forked process now; collect its result later.

    Parameters
    ----------
    fn : callable
        Called without arguments in the child; its result must be picklable.
    label : str
        What runs (for messages), e.g. ``"stage 'study'"``.
    niceness : int, optional
        Added to the child's nice value (POSIX ``nice``): work that nothing waits for
        until the end of a run yields the cores to the work that is waited for when both
        want them. Default 0, this process's priority.

    Raises
    ------
    ValueError
        Where the ``fork`` start method does not exist (check
        :func:`debist.core.forking.fork_workers` first).
    """

    def __init__(self, fn: Callable[[], Any], label: str, *, niceness: int = 0):
        ctx = fork_context(quiet=True)
        self.label = label
        self._recv, send = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(
            target=_child, args=(fn, send, self._recv, int(niceness)), name=label
        )
        self._proc.start()
        send.close()

    def result(self) -> Any:
        """Wait for the child; return its result or raise what it raised.

        Its recorded warnings are issued here first.

        Returns
        -------
        object
            What ``fn`` returned.

        Raises
        ------
        ArtifactError
            If the child ended without a result (killed, or it crashed).
        BaseException
            What ``fn`` raised in the child.
        """
        try:
            ok, value, caught = self._recv.recv()
        except EOFError:
            self._proc.join()
            raise ArtifactError(
                f"{self.label} ran in its own process, which ended without a result "
                f"(exit code {self._proc.exitcode}); its previous artifacts stay"
            ) from None
        except Exception as exc:  # a result or exception that does not unpickle
            self._proc.join()
            raise ArtifactError(f"{self.label}: its result could not be read: {exc}") from exc
        finally:
            self._recv.close()
        self._proc.join()
        replay_warnings(caught)
        if not ok:
            raise value
        return value

    def stop(self) -> None:
        """End the child if it still runs (SIGTERM, then SIGKILL after :data:`STOP_GRACE`).

        A stage's swap of its folder is crash-safe, so a stage stopped halfway leaves its
        previous artifacts or leftovers the next run resolves.
        """
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(STOP_GRACE)
            if self._proc.is_alive():
                self._proc.kill()
        self._proc.join()
        self._recv.close()
