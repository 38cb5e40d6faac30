"""Presentation of results.

The terminal tables, the HTML report and batch index, the figures, and their rendering to PNG
in forked processes.
"""
