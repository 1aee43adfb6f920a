"""SIEMENS SINUMERIK 840D sl: G-code programs under TRAORI, ``$TC_CARR`` kinematic-record
edits (fine offsets and axis vectors), CEC compensation tables, and their readers.

References: Commissioning Manual 12/2017 p.572–573 (``$TC_CARR``, table axes entered
reversed); Function Manual K3 03/2013 §4.4 (CEC, machine-axis names p.248).
"""

from .carr import FINE, VECTOR, read_carr, read_lines  # noqa: F401
from .cec import _cec_text, read_cec  # noqa: F401
from .controller import Sinumerik840D  # noqa: F401
