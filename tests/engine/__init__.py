"""Tests of debist.engine."""
