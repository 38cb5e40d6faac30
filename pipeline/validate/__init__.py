"""Section 5 of Masoud & Maas 2025: the validation of identified models by free-run simulation.

:mod:`.config` (the ``[validate]`` table), :mod:`.freerun` (free runs scored by NRMSE, Eq. 41,
replicates and the divergence limit) and :mod:`.datasets` (the validation data sets built
from the stages' tables). This package's ``__init__`` imports none of them, so that checking
a workflow's ``[validate]`` table does not load the simulator.
"""
