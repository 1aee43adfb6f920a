"""Statistics on the model and the data: the fit (identify) and its result, the noise, the
tests, the spectrum, diagnose in its steps, and the gate before an edit. Nothing here imports
a controller, a program, the motion check or the history: an advisor comes from the caller."""
