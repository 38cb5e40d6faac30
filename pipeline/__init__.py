"""debist: rig logs of bistable dielectric-elastomer actuators to validated dynamic models.

The library behind the ``debist`` command line, and its Python API (:mod:`debist.api`)::

    import debist

    result = debist.run("workflows/silverbox.toml")
    result.nrmse                 # the NRMSE table the CLI prints, in percent
    result.model.simulate(t, v, q0=0.0, q_dot0=0.0)

Every stage is a pure function in one of the sub-packages; file input and output live in
:mod:`debist.core.artifacts` and the readers of :mod:`debist.ingest`. The names below load
lazily, so ``import debist`` stays cheap (the command line imports what it needs).

References
----------
Masoud, A. & Maas, J. (2025). Data-driven modeling and identification of a bistable
soft-robot element based on dielectric elastomer. Front. Robot. AI 12.
"""

__version__ = "0.1.0"

__all__ = [
    "Export",
    "FleetResult",
    "Model",
    "NrmseTable",
    "ProgressEvent",
    "Result",
    "Verification",
    "__version__",
    "batch_index",
    "batch_table",
    "diff",
    "example_workflow",
    "export_model",
    "find_workflows",
    "find_zoos",
    "fleet",
    "init_workflow",
    "list_channels",
    "load_model",
    "load_workflow",
    "missing_output",
    "open_run",
    "run",
    "run_batch",
    "run_blocker",
    "status",
    "verify",
    "workflow_schema",
    "workflow_stages",
    "zoo",
    "zoo_report",
]


#: Names of ``__all__`` defined outside :mod:`debist.api` (the API loads them when needed).
_HOMES = {"NrmseTable": "debist.report.frames"}


def __getattr__(name: str):
    """Load the API's names on first use (PEP 562), keeping ``import debist`` light."""
    if name in __all__:
        # import_module, not an import statement: a stage's code fingerprint follows import
        # statements (debist.engine.fingerprint), and no stage runs the API that this loads.
        from importlib import import_module

        return getattr(import_module(_HOMES.get(name, "debist.api")), name)
    raise AttributeError(f"module 'debist' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
