"""debist's tests, one package per package of debist (tests/core for debist.core, ...)."""
