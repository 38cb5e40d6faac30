"""Virtual rig: realistic rig logs of bistable DE prototypes with known truth.

The rig simulates the full dynamic model of Section 3 (:mod:`debist.physics`) plus the
effects the analytical model leaves out, drives it with excitation profiles, and writes the
result as a dSPACE ControlDesk recording so that the ingest stage reads it like a lab's file.
"""
