"""Section 3 of Masoud & Maas 2025: the physics-based model of the bistable DE actuator."""
