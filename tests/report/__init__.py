"""Tests of debist.report."""
