"""The set-up in motion: a program's blocks moved through the machine with the R-test (or the
probe and its sphere) in place, checked for travel, feeds and clearance."""
