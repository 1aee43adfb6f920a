#!/usr/bin/env bash
# A touch probe and a calibration sphere, from the program to the kinematics edit:
# write the probing program and check it, fit the probe log it writes, see what is missing,
# and write the control's edit.
#   PY=.venv/bin/python examples/probe.sh [WORKDIR]      (from the repository root)
# (`python -m compgen`, not `compgen`: in bash that word is a shell builtin.)
# Here the log is simulated from examples/truth-seed-session.json (the seed's errors and a
# hidden 2/rev radial error motion of C) at 1 µm trigger noise; on a machine, it is the
# file PROBE_LOG the program writes on the control.
set -euo pipefail
work=${1:-probe}
mkdir -p "$work"
cg() { "${PY:-python3}" -m compgen "$@"; }
m=machines/ac-trunnion-itnc530.toml

echo "== 1. the probing program (K4, K1, K2 at 12 poses each, 5 touches a pose), checked"
cg probe-program --machine $m --path all -o "$work/PROBE.H" --force
cg check-program --machine $m "$work/PROBE.H"

echo "== 2. the probe log (simulated here) and the fit of the 11 location errors"
cg simulate --machine $m --truth examples/truth-seed-session.json --device probe --noise-um 1 \
  --seed 2026 -o "$work/PROBE_LOG.csv" --force
cg fit --machine $m "$work/PROBE_LOG.csv" -o "$work/fit.json" --force

echo "== 3. where does the model fail? (36 poses do not tell C's 2/rev radial motion from two rivals;"
echo "   this session's truth, EXC:h2, is added here: on a machine, follow what diagnose says of rivals)"
cg diagnose --from "$work/fit.json" || true
cg fit --from "$work/fit.json" --add EXC:h2 -o "$work/fit2.json" --force
cg diagnose --from "$work/fit2.json"

echo "== 4. the kinematics edit for the control's table"
cg kinematics --from "$work/fit2.json" --current examples/itnc530-current.TAB -o "$work/KIN.TAB" --force
