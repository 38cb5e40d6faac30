"""Tests of the command line (debist.cli), the Python API (debist.api) and the package."""
