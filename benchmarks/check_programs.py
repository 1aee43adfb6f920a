"""Every measuring program compgen writes for the bundled machines, checked by the motion
simulator: moves, estimated run time, closest approach to the set-up, time of the check.
A benchmark, not a test (tests/motion/test_motion.py checks the same programs pass).

    python benchmarks/check_programs.py
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from compgen.configuration.machine_file import load_machine
from compgen.controllers.programs import measure_program
from compgen.controllers.registry import controller
from compgen.model.frames import safe_height
from compgen.model.paths import generate

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    print(f"{'machine':<8}{'controller':<15}{'mode':<6}{'path':<7}{'moves':>6}{'min':>7}"
          f"{'closest mm':>12}  {'between':<28}{'check s':>8}")
    for key, file in (("seed", "ac-trunnion-itnc530.toml"), ("B/C", "bc-table-sinumerik840d.toml")):
        machine = load_machine(ROOT / "machines" / file)
        machine = replace(machine, program=replace(machine.program, tool="7"))   # LinuxCNC: a number
        print(f"{key}: safe height {safe_height(machine):g} mm above the rotary axes")
        for ctl in ("itnc530", "sinumerik840d", "linuxcnc"):
            for mode in ("tcpm", "axes"):
                for path in (["K4"], ["K1", "K2"], list(machine.paths)):
                    emitted = measure_program(machine, generate(machine, path), "+".join(path), ctl, mode,
                                              "RT", "0", "d")
                    text = emitted.files[controller(ctl).program_ext]
                    t0 = time.perf_counter()
                    # as check-program runs it: the control's modulo rule and angle sense; LinuxCNC's
                    # configuration, not the program, says the kinematics it runs under
                    c = controller(ctl)
                    result = c.check(machine, c.blocks(text, None if c.tcp_switchable else mode))
                    seconds = time.perf_counter() - t0
                    label = "all" if len(path) == 3 else ",".join(path)
                    print(f"{key:<8}{ctl:<15}{mode:<6}{label:<7}{result.blocks:>6}{result.seconds / 60:>7.1f}"
                          f"{result.closest_mm:>12.1f}  {result.closest_at:<28}{seconds:>8.2f}")


if __name__ == "__main__":
    main()
