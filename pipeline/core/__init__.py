"""The base layer: what every other package of debist may import, and which imports none of them.

Errors and warnings (:mod:`.errors`), checks of names and arguments (:mod:`.names`,
:mod:`.arguments`), the configuration mechanism of the workflow sections (:mod:`.config`),
units (:mod:`.units`), error measures (:mod:`.metrics`), canonical rig-log tables
(:mod:`.tables`), file formats, hashing and the run folder's artifacts (:mod:`.fileformats`,
:mod:`.artifacts`), the user cache (:mod:`.cache`), memory preflight (:mod:`.preflight`), the
progress protocol (:mod:`.progress`), worker processes (:mod:`.forking`) and fault points
(:mod:`.faults`). This package's ``__init__`` imports none of them.
"""
