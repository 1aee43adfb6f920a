"""What both test displays do first, as an operator does: switch LinuxCNC on and home it.
(Imported from the display scripts, which LinuxCNC runs with /usr/bin/python3.)"""
import time

import hal
import linuxcnc


class Display:
    """A HAL component named ``name`` (LinuxCNC waits for a display's) with LinuxCNC's status
    and command channels."""

    def __init__(self, name: str):
        self.s, self.c = linuxcnc.stat(), linuxcnc.command()
        self.component = hal.component(name)
        self.component.ready()

    def wait(self, cond, seconds=30):
        end = time.time() + seconds
        while time.time() < end:
            self.s.poll()
            if cond():
                return True
            time.sleep(0.01)
        raise TimeoutError("LinuxCNC did not reach the expected state")

    def on_and_homed(self) -> None:
        s, c = self.s, self.c
        c.state(linuxcnc.STATE_ESTOP_RESET)
        c.state(linuxcnc.STATE_ON)
        self.wait(lambda: s.task_state == linuxcnc.STATE_ON)
        c.mode(linuxcnc.MODE_MANUAL)
        c.teleop_enable(0)
        c.home(-1)
        self.wait(lambda: all(s.homed[:s.joints]))
