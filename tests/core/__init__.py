"""Tests of debist.core."""
