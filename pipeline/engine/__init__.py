"""The stage machinery, apart from the domain code.

The stage registry, the runner and its content-hash cache, code fingerprints, the output folder
(owner, lock, recovery, digest), run diffs, batches on Dask, fleets and plant zoos. The
artifacts and their file formats, memory preflight, progress and the user cache are the base
layer's (:mod:`debist.core`).
"""
