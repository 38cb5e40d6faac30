"""Tests of debist.export."""
