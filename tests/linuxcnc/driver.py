#!/usr/bin/python3
"""The 'display' of the test configuration: switch on, home, run $COMPGEN_NGC in AUTO,
and write the settled joint positions per program line to $COMPGEN_JOINTS."""
import os
import time

import linuxcnc

s, c = linuxcnc.stat(), linuxcnc.command()


def wait(cond, seconds=30):
    end = time.time() + seconds
    while time.time() < end:
        s.poll()
        if cond():
            return True
        time.sleep(0.01)
    raise TimeoutError("LinuxCNC did not reach the expected state")


with open(os.environ["COMPGEN_JOINTS"], "w") as out:
    try:
        c.state(linuxcnc.STATE_ESTOP_RESET)
        c.state(linuxcnc.STATE_ON)
        wait(lambda: s.task_state == linuxcnc.STATE_ON)
        c.mode(linuxcnc.MODE_MANUAL)
        c.teleop_enable(0)
        c.home(-1)
        wait(lambda: all(s.homed[:5]))
        c.mode(linuxcnc.MODE_AUTO)
        wait(lambda: s.task_mode == linuxcnc.MODE_AUTO)
        c.program_open(os.environ["COMPGEN_NGC"])
        c.auto(linuxcnc.AUTO_RUN, 0)
        wait(lambda: s.interp_state != linuxcnc.INTERP_IDLE, 10)
        settled = {}
        end = time.time() + 600
        while time.time() < end:
            s.poll()
            if s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0:
                break
            if s.current_vel == 0:
                settled[s.motion_line] = list(s.joint_actual_position[:5])
            time.sleep(0.002)
        for line in sorted(settled):
            out.write(f"{line} " + " ".join(f"{v:.9f}" for v in settled[line]) + "\n")
        out.write("done\n")
    except Exception as exc:   # the test reads this line and fails with it
        out.write(f"error {exc!r}\n")
