"""debist: rig logs of bistable dielectric-elastomer actuators to validated dynamic models.

The library behind the ``debist`` command line. Every stage is a pure function in
one of the sub-packages; file input and output live in :mod:`debist.artifacts`
and the readers of :mod:`debist.ingest`.

References
----------
Masoud, A. & Maas, J. (2025). Data-driven modeling and identification of a bistable
soft-robot element based on dielectric elastomer. Front. Robot. AI 12.
"""

__version__ = "0.1.0"
