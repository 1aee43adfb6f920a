#!/usr/bin/python3
"""The 'display' of the test configuration: switch on, home, run $COMPGEN_NGC in AUTO,
and write to $COMPGEN_JOINTS every time the joints rested, in the order they did: the
program line the status named, how many polls they held, the joints' commanded positions,
then their motor commands (with the joint compensation tables' trims), of the joints
$COMPGEN_READ_JOINTS names (default 0 to 4)."""
import os
import time

import hal
import linuxcnc
from display import Display

display = Display("compgen-driver")
read = [int(j) for j in os.environ.get("COMPGEN_READ_JOINTS", "0 1 2 3 4").split()]
s, c, wait = display.s, display.c, display.wait
errors = linuxcnc.error_channel()     # the operator's messages: an (abort, ...) says why it stopped
messages = []


def heard() -> bool:
    """Keep the operator's message LinuxCNC sent, if any: whether there was one."""
    message = errors.poll()
    if message:
        messages.append(" ".join(str(message[1]).split()))
    return bool(message)


with open(os.environ["COMPGEN_JOINTS"], "w") as out:
    try:
        display.on_and_homed()
        # every joint out and back, as homing moves it on a real machine: a joint's
        # compensation table applies once it has moved (control.c keeps the last trim while
        # a joint stands, and it starts at zero)
        axes = linuxcnc.ini(os.environ["INI_FILE_NAME"]).find("TRAJ", "COORDINATES")
        c.mode(linuxcnc.MODE_MDI)
        wait(lambda: s.task_mode == linuxcnc.MODE_MDI)
        for value in (1, 0):
            c.mdi("G90 G0 " + " ".join(f"{a}{value}" for a in axes))
            c.wait_complete(30)
            wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.inpos)
        c.mode(linuxcnc.MODE_AUTO)
        wait(lambda: s.task_mode == linuxcnc.MODE_AUTO)
        c.program_open(os.environ["COMPGEN_NGC"])
        c.auto(linuxcnc.AUTO_RUN, 0)
        # running, or stopped at once by the program's own guard (its message says so)
        wait(lambda: heard() or s.interp_state != linuxcnc.INTERP_IDLE, 10)
        rests, last, stops = [], None, 0
        still, line = 0, 0         # polls the joints have held at rest; the status's line then
        end = time.time() + 600
        while time.time() < end:
            s.poll()
            heard()
            if s.interp_state == linuxcnc.INTERP_IDLE and s.queue == 0:
                break
            if s.paused:           # the program's preset check (M0): the operator goes on
                stops += 1
                c.auto(linuxcnc.AUTO_RESUME)
                wait(lambda: not s.paused, 10)
                continue
            # the joints, their motor commands and the motion's speed read from HAL (the
            # real-time side): at rest when the speed is nil and the joints unchanged since the
            # last sample. Not the status buffer's speed: under load it lags HAL by a block or
            # more (a CI run saw no rest at all at one pose, its 0.1 s dwell read as moving).
            # The line is the status's (HAL's motion.program-line stays 0 here), which can lag
            # or lead likewise. Every rest is kept, in time order, for the tests to tell a
            # pose's dwell (50 polls at the tests' 0.1 s) by the program's words, the order and
            # the length, from a starved real-time thread holding HAL's values mid-move
            now = [hal.get_value(f"joint.{j}.{pin}")
                   for pin in ("pos-cmd", "motor-pos-cmd") for j in read]
            if hal.get_value("motion.current-vel") == 0 and now == last:
                still, line = still + 1, s.motion_line
            elif still:
                rests.append((line, still, last))
                still = 0
            last = now
            time.sleep(0.002)
        if still:
            rests.append((line, still, last))
        for line, polls, values in rests:
            out.write(f"{line} {polls} " + " ".join(f"{v:.9f}" for v in values) + "\n")
        out.writelines(f"message {m}\n" for m in messages)
        out.write(f"stops {stops}\ndone\n")
    except Exception as exc:   # the test reads this line and fails with it
        out.write(f"error {exc!r}\n")
