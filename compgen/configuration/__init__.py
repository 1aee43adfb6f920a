"""A machine file (it names its control) and a fit's files: reloading what a fit was made
from, and what a new fit or a refit fits."""
