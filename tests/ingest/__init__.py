"""Tests of debist.ingest."""
