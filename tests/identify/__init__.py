"""Tests of debist.identify."""
