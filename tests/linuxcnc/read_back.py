#!/usr/bin/python3
"""The 'display' that reads a configuration back from LinuxCNC itself: switch on, home,
then write to $COMPGEN_JOINTS, as JSON, what `halcmd getp` says of each pin in
$COMPGEN_PINS (and its full value, hal.get_value) and, at each joint position in
$COMPGEN_POSITIONS (reached by MDI G0 under
the kinematics active at start), the joints' commanded positions and motor commands: their
difference is the trim of the joints' compensation tables."""

import json
import os
import subprocess
import time

import hal
import linuxcnc
from display import Display

display = Display("compgen-read-back")
s, c, wait = display.s, display.c, display.wait
out = {}
try:
    display.on_and_homed()
    out["values"] = {p: hal.get_value(p) for p in os.environ["COMPGEN_PINS"].split(",")}
    out["pins"] = {
        p: subprocess.run(["halcmd", "getp", p], capture_output=True, text=True, check=True).stdout.strip()
        for p in os.environ["COMPGEN_PINS"].split(",")
    }
    axes = linuxcnc.ini(os.environ["INI_FILE_NAME"]).find("TRAJ", "COORDINATES").replace(" ", "")
    c.mode(linuxcnc.MODE_MDI)
    wait(lambda: s.task_mode == linuxcnc.MODE_MDI)
    out["joints"] = []
    for at in json.loads(os.environ["COMPGEN_POSITIONS"]):
        c.mdi("G90 G0 " + " ".join(f"{a}{v:.6f}" for a, v in zip(axes, at, strict=True)))
        c.wait_complete(60)
        wait(lambda: s.interp_state == linuxcnc.INTERP_IDLE and s.inpos)
        time.sleep(0.05)
        out["joints"].append(
            [[hal.get_value(f"joint.{j}.{pin}") for j in range(5)] for pin in ("pos-cmd", "motor-pos-cmd")]
        )
    out["done"] = True
except Exception as exc:  # the test reads this and fails with it
    out["error"] = repr(exc)
with open(os.environ["COMPGEN_JOINTS"], "w") as f:
    json.dump(out, f)
# the display ends: the start script shuts LinuxCNC down
