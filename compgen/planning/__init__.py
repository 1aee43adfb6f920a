"""The plan of measurements: what this machine can measure next, each proposal's program
written for its control and passed by the motion check (``advice``, handed to identify and
diagnose through the statistics' own protocols)."""
