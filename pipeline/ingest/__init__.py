"""Ingest: rig logs into canonical, checked tables in SI units.

Reads MAT v5/v7.3 files (dSPACE ControlDesk recordings or plain variables), delimited
text, Parquet and ASAM MDF (MF4, with the optional asammdf).

Public API::

    from debist.ingest.spec import IngestSpec
    from debist.ingest.load import load_rig_log, RIG_LOG_FORMATS
    spec = IngestSpec.from_dict(section)            # WorkflowError on a bad key/value
    segments = load_rig_log(path, spec)             # list[pandas.DataFrame]

Every table has the columns ``t, q, v1, ..., vN, <extras sorted>`` (float64, RangeIndex,
SI units, time as recorded and strictly increasing) and ``attrs`` describing where it came
from. The user documentation of the accepted formats, the channel mapping and the units
is ``data/README.md``.

The modules, one concern each: :mod:`.spec` (configuration), :mod:`.units`,
:mod:`.detect` (magic bytes), :mod:`.mat` / :mod:`.mat73` / :mod:`.text` /
:mod:`.parquet` / :mod:`.mf4` (readers), :mod:`.cache` (one read per file and stage),
:mod:`.channels` (mapping and unit conversion), :mod:`.checks` (validation),
:mod:`.resample`, :mod:`.assemble` (the canonical table), :mod:`.load` (one rig log
through all of them). This package's ``__init__`` imports none of them, so that checking a
workflow's ``[ingest]`` table (:mod:`.spec`, :mod:`.units`) does not load the readers.
"""
