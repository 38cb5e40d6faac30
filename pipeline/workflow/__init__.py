"""Workflow files.

Loading and overrides (loader), the typed schema of every section (schema) and the one
configuration base the sections share (config).
"""
