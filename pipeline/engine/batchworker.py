"""The set-up of a batch's Dask worker processes (a Dask preload module).

A terminal's Ctrl-C goes to every process of the foreground process group: the ``debist
batch`` command and its local cluster's worker processes alike. The command stops the batch
and says so in one line; a worker process that took the signal itself would stop its
workflow mid-stage and print its event loop's traceback past that line. :func:`dask_setup`
makes each worker process ignore SIGINT: the command, its only receiver, closes the cluster,
and the cluster's nannies stop their workers.

References
----------
dask.distributed documentation, "Customize initialization" (preload scripts, ``dask_setup``),
https://distributed.dask.org/en/stable/setup.html; POSIX ``signal(2)``, ``setpgid(2)``
(a terminal's interrupt character signals the foreground process group).
"""

from __future__ import annotations

import signal
import threading
from typing import Any

__all__ = ["dask_setup"]


def dask_setup(worker: Any) -> None:
    """Make this worker process ignore SIGINT (Ctrl-C): the batch command handles it.

    Called by Dask in each worker process when the worker starts (also one that a nanny
    starts again after a death), on the thread of its event loop, the process's main thread.

    Parameters
    ----------
    worker : distributed.Worker
        The worker (not used).
    """
    del worker
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
