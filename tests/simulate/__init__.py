"""Tests of debist.simulate."""
