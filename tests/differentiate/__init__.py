"""Tests of debist.differentiate."""
