#!/usr/bin/env bash
# The whole loop on the seed machine (iTNC 530): a session with Table 4 location errors and
# a hidden 2/rev radial error motion of C (examples/seed-session.csv), fit, diagnose, add,
# emit the kinematics edit, apply it (simulated: the control loads the table), measure
# again, and compare the prediction with the "measured" result.
#   PY=.venv/bin/python examples/end-to-end.sh [WORKDIR]     (from the repository root)
set -euo pipefail
work=${1:-end-to-end}
mkdir -p "$work"
cg() { "${PY:-python3}" -m compgen "$@"; }
M=machines/ac-trunnion-itnc530.toml

echo "== fit, diagnose, add the effect it names"
cg fit --machine $M examples/seed-session.csv -o "$work/fit.json" --force | grep "residual RMS"
cg diagnose --from "$work/fit.json" | grep -A1 " 1\. "
cg fit --from "$work/fit.json" --add EXC:h2 -o "$work/fit2.json" --force | grep "residual RMS"

echo "== the kinematics edit for the iTNC 530, from its current table"
cg kinematics --from "$work/fit2.json" --current examples/itnc530-current.TAB \
  -o "$work/KINEMATIC.TAB" --force | grep -E "line at its pivot|not compensable|wrote"

echo "== prediction before touching the control"
cg compare --from "$work/fit2.json"

echo "== the control loads the table; measure K4, K1, K2 again (simulated, 0.5 um noise)"
cg simulate --machine $M --truth examples/truth-seed-session.json --edit "$work/KINEMATIC.TAB" \
  --noise-um 0.5 --seed 7 -o "$work/post.csv" --force

echo "== predicted against measured"
cg compare --from "$work/fit2.json" --post "$work/post.csv"
