"""Fault injection for the crash-safety tests: kill the process at a named point.

The environment variable ``DEBIST_FAULT`` holds comma-separated points, each
``<point>[@<workflow name>][=<signal>]``. When the code passes a point that is listed
(for that workflow, when one is named), the process sends itself the signal: ``KILL``
(the default) is what the out-of-memory killer or a power cut does, no clean-up, no
``finally``; ``TERM`` is a polite stop (handled by the CLI like Ctrl-C); ``STOP`` pauses the
process until it gets ``SIGCONT`` (a run that holds its lock while a test starts another).
Tests use it instead of sleeps and timing to stop a run between two file-system operations.

Points passed by debist:

* ``swap:<stage>:moved-old``: a stage's previous folder was moved aside, the new one not
  yet in place;
* ``swap:<stage>:moved-new``: the new folder is in place, the previous one not yet removed;
* ``swap:<stage>:written``: the new outputs and manifest are written to the temporary
  folder, nothing is swapped yet;
* ``stage:<stage>:start``: a stage is about to run (used to kill a batch worker).

With ``DEBIST_FAULT_ONCE`` naming a file, a point fires only in the process that creates
that file first (a worker killed once, whose retry then runs through).

Without ``DEBIST_FAULT`` a point costs one dictionary lookup.

References
----------
The "crash-only software" testing practice of injecting faults at named points
(Candea & Fox, HotOS 2003).
"""

from __future__ import annotations

import os
import signal

__all__ = ["ENV", "ONCE", "fault_point"]

#: The environment variable that lists the points.
ENV = "DEBIST_FAULT"
#: The environment variable naming a file whose creation lets a point fire once only.
ONCE = "DEBIST_FAULT_ONCE"


def fault_point(point: str, workflow: str | None = None) -> None:
    """Send the process a signal (SIGKILL by default) if ``point`` is listed in ``DEBIST_FAULT``.

    Parameters
    ----------
    point : str
        Name of the point, e.g. ``"swap:identify:moved-old"``.
    workflow : str, optional
        Name of the workflow being run; a listed ``point@name`` only fires for it.

    Examples
    --------
    >>> fault_point("swap:identify:moved-old")  # not listed: nothing happens
    """
    spec = os.environ.get(ENV)
    if not spec:
        return
    for item in spec.split(","):
        item, _, sig = item.strip().partition("=")
        name, _, only = item.partition("@")
        if name == point and (not only or only == workflow):
            marker = os.environ.get(ONCE)
            if marker:
                try:
                    os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
                except FileExistsError:
                    return  # fired already
            os.kill(os.getpid(), getattr(signal, f"SIG{sig or 'KILL'}"))
