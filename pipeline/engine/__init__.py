"""The stage machinery, apart from the domain code.

The runner and its content-hash cache, code fingerprints, the output folder (owner, lock,
recovery), run diffs, batches on Dask, fleets and plant zoos. The artifacts and their file
formats, memory preflight, progress and the user cache are the base layer's
(:mod:`debist.core`); the stage registry is :mod:`debist.stages.registry`.
"""
