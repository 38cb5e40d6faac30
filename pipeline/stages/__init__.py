"""The pipeline's stages, one module each: pure functions from arrays and settings to results.

Each stage module holds the stage's pure ``run_<stage>`` function (arrays and configuration
in, a result out; no file IO, no printing; compare has two, ``run_peers`` and
``with_rbf_rows``, whose first can run ahead) and an ``execute(ctx)`` adapter that takes the
stage's inputs from a :class:`StageInputs` (the runner, which reads them through
:mod:`debist.core.artifacts`) and returns a :class:`StageOutput` for the runner to write. Only
ingest reads files itself, because reading rig logs is what it is for.

The registry :data:`debist.stages.registry.STAGES` names each stage's module; a stage's key
hashes the source of that module and of every ``pipeline`` module it imports, transitively
(:func:`debist.engine.fingerprint.code_fingerprint`), so this package's ``__init__`` imports
nothing: a stage's code is exactly what its own module reaches. Beside the stage modules sit
what several of them share: :mod:`.registry` (the stage graph), :mod:`.studies` (the
hyper-parameter studies of the study stage) and :mod:`.sindy_choice`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:  # typing only: stage modules must not import the workflow loader
    import pandas as pd

    from debist.physics.params import PrototypeParams
    from debist.workflow.loader import Workflow

__all__ = ["StageInputs", "StageOutput"]


@dataclass(frozen=True)
class StageOutput:
    """What a stage hands to the runner to write.

    Attributes
    ----------
    outputs : dict of str to object
        Output path relative to the stage folder to value: a pandas DataFrame (Parquet),
        :class:`debist.core.artifacts.H5Tree`, :class:`debist.core.artifacts.Figure`,
        :class:`debist.core.artifacts.FileWriter`, ``str`` or ``bytes``.
    summary : dict
        Small JSON-compatible results the reports print (written as the hashed output
        ``summary.json``); reproducible values only, no wall times.
    timings : dict of str to float
        Wall times of parts of the stage [s] (written to the unhashed ``timings.json``).

    Examples
    --------
    >>> out = StageOutput({"notes.txt": "two data sets"}, {"n_datasets": 2})
    >>> out.summary, out.timings
    ({'n_datasets': 2}, {})
    """

    outputs: dict[str, Any]
    summary: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


class StageInputs(Protocol):
    """What a stage's ``execute`` may read: the workflow and the upstream stages' artifacts.

    Implemented by :class:`debist.engine.runner.Runner`; every read goes through
    :mod:`debist.core.artifacts`.
    """

    wf: Workflow

    def section(self, name: str) -> dict[str, Any]:
        """Return a section of the workflow (empty when absent)."""

    def physics(self) -> PrototypeParams | None:
        """Return the prototype of ``[physics]``, or None without that section."""

    def tables(self, stage: str) -> dict[str, pd.DataFrame]:
        """Return the per-data-set Parquet tables of an upstream stage."""

    def read_h5(self, stage: str, rel: str) -> dict[str, Any]:
        """Return an upstream HDF5 artifact as a nested dict."""

    def read_parquet(self, stage: str, rel: str) -> pd.DataFrame:
        """Return an upstream Parquet artifact."""

    def stage_config(self, stage: str) -> dict[str, Any]:
        """Return the resolved configuration of a stage (what its key hashes)."""

    def load_ahead(self) -> None:
        """Load here what the stages still to run will load (their code, their ``preload``).

        For a stage that waits on its worker processes: the loading takes a core they
        leave free instead of the time of the stages after it. Decides nothing.
        """
