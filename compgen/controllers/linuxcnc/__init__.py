"""LinuxCNC with the trt kinematics (``xyzac-trt-kins``, ``xyzbc-trt-kins``): G-code
programs and HAL edits of the kinematics pins, and their reader.

The pins (``src/emc/kinematics/trtfuncs.c``): C turns about the line through the rot
point, the tilting axis about the line through the rot point plus the offsets. They hold
axis-line positions only: angular location errors cannot be expressed.

An axis's error along itself (a linear positioning error, a rotary axis's angle error) goes
to the joint's compensation table, ``[JOINT_n] COMP_FILE`` with ``COMP_FILE_TYPE = 1``:
lines "nominal trim-up trim-down" in machine units, ascending, at most 256
(``EMCMOT_COMP_SIZE``, ``src/emc/motion/motion.h``); the trim, interpolated, is added to the
joint's command (``src/emc/motion/control.c``); beyond the last line the end trim holds. The
loader reads triplets up to the first line that is not one (``usrmotintf.cc``), so compgen's
notes close the file. The tables use the trt modules' joint numbers for their default
coordinates (X Y Z, the tilting axis, C: joints 0–4), as LinuxCNC prints them at start.
"""


from .controller import LinuxCNC  # noqa: F401
from .heads import (  # noqa: F401
    HEAD_MODULES,
    HeadModule,
    head_lines,
    head_module,
    nominal_pins,
    pin_names,
    pin_tolerance,
    trt_module,
)
from .pins import SETP, SETS, held_pins, read_hal, read_lines  # noqa: F401
from .reader import LINE_MAX, PIN_GUARD, head_guard, offsets_guard, program_blocks  # noqa: F401
from .tables import COMP_ENTRIES, joint_number, loaded_joint_tables, read_comp  # noqa: F401
