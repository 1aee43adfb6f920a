#!/usr/bin/python3
"""The 'display' of the test configuration: switch on, home, run $COMPGEN_NGC in AUTO,
and write to $COMPGEN_JOINTS every time the joints rested, in the order they did: the
program line of the move that brought them there, how many servo periods they held, the
joints' commanded positions, then their motor commands (with the joint compensation
tables' trims), of the joints $COMPGEN_READ_JOINTS names (default 0 to 4).

The joints, the speed and the line are sampled by HAL's own sampler in the servo thread,
every period, into a FIFO this script drains: a rest is seen whole, under its own line,
however late this script runs. Polled from here, a pose's 0.1 s dwell was missed outright
when a loaded machine kept the script off the CPU for longer (a CI run), and the status's
line lagged or led the motion by blocks."""
import os
import subprocess
import time

import hal
import linuxcnc
from display import Display

display = Display("compgen-driver")
read = [int(j) for j in os.environ.get("COMPGEN_READ_JOINTS", "0 1 2 3 4").split()]
s, c, wait = display.s, display.c, display.wait
errors = linuxcnc.error_channel()     # the operator's messages: an (abort, ...) says why it stopped
messages = []
SAMPLER_KEY = 0x48534130    # LinuxCNC's streamer.h: SAMPLER_SHMEM_KEY, sampler 0's FIFO
DEPTH = 16384               # servo periods (1 ms) of slack before the FIFO overruns


def halcmd(*words: str) -> str:
    return subprocess.run(["halcmd", "-s", *words], check=True, capture_output=True, text=True).stdout


def sample(pins: list) -> "hal.stream":
    """Load a sampler of ``pins`` (floats, then one s32) into the servo thread; its FIFO."""
    halcmd("loadrt", "sampler", f"depth={DEPTH}", "cfg=" + "f" * (len(pins) - 1) + "s")
    halcmd("addf", "sampler.0", "servo-thread")
    for k, pin in enumerate(pins):
        shown = halcmd("show", "pin", pin).split()
        arrow = [i for i, w in enumerate(shown) if w in ("==>", "<==", "<=>")]
        if arrow:                                # on a signal already: the sampler reads it too
            halcmd("net", shown[arrow[0] + 1], f"sampler.0.pin.{k}")
        else:
            halcmd("net", f"compgen-sample-{k}", pin, f"sampler.0.pin.{k}")
    return hal.stream(display.component, SAMPLER_KEY)


class Rests:
    """The rests in the sampled periods, in time order: (line, periods, joints). A rest's
    line is HAL's motion.program-line of the last move before it (the pin holds the line of
    the move under way; it reads 0 at rest): a pose's dwell is filed under the pose's block."""

    def __init__(self):
        self.seen, self.still, self.line, self.moved_by, self.last = [], 0, 0, 0, None

    def drain(self, fifo) -> None:
        """Read the FIFO to its end: at rest where the speed is nil and the joints are the
        last period's."""
        while (got := fifo.read()) is not None:
            *now, speed, line = got
            self.moved_by = line or self.moved_by
            if speed == 0 and now == self.last:
                if not self.still:
                    self.line = self.moved_by
                self.still += 1
            else:
                self.end()
            self.last = now

    def end(self) -> None:
        if self.still:
            self.seen.append((self.line, self.still, self.last))
            self.still = 0


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
        # every period from here on: the joints, their motor commands, the motion's speed and line
        fifo = sample([f"joint.{j}.{pin}" for pin in ("pos-cmd", "motor-pos-cmd") for j in read]
                      + ["motion.current-vel", "motion.program-line"])
        c.mode(linuxcnc.MODE_AUTO)
        wait(lambda: s.task_mode == linuxcnc.MODE_AUTO)
        c.program_open(os.environ["COMPGEN_NGC"])
        c.auto(linuxcnc.AUTO_RUN, 0)
        # running, or stopped at once by the program's own guard (its message says so)
        wait(lambda: heard() or s.interp_state != linuxcnc.INTERP_IDLE, 10)
        rests, stops = Rests(), 0
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
            rests.drain(fifo)
            time.sleep(0.01)
        time.sleep(0.05)           # the periods after the end reach the FIFO
        rests.drain(fifo)
        if hal.get_value("sampler.0.overruns"):
            raise RuntimeError(f"the sampler's FIFO overran {hal.get_value('sampler.0.overruns')} times")
        rests.end()
        for line, periods, values in rests.seen:
            out.write(f"{line} {periods} " + " ".join(f"{v:.9f}" for v in values) + "\n")
        out.writelines(f"message {m}\n" for m in messages)
        out.write(f"stops {stops}\ndone\n")
    except Exception as exc:   # the test reads this line and fails with it
        out.write(f"error {exc!r}\n")
