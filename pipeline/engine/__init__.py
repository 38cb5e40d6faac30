"""The stage machinery, apart from the domain code.

The stage registry, the runner and its content-hash cache, artifacts and their file formats,
code fingerprints, the output folder (owner, lock, recovery, digest), memory preflight, batches
on Dask, progress.
"""
