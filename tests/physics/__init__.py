"""Tests of debist.physics."""
