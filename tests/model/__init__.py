"""Tests of debist.model."""
