"""Tests of debist.rig."""
