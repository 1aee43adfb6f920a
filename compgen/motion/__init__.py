"""The motion check: a program's blocks (``blocks``, as each control's reader gives them)
moved through the machine with the R-test (or the probe and its sphere) in place, checked for
travel, feeds and clearance (``check``)."""
