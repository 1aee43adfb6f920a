"""Measurements as the model reads them: R-test CSV v1, touch-probe logs (sphere centres),
the ``Measurements`` set that joins them, and simulated sessions."""
