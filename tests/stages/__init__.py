"""Tests of debist.stages."""
