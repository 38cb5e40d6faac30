"""Tests of debist.workflow."""
