"""Tests of debist.validate."""
