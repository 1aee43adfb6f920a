#!/usr/bin/env bash
# Model discovery on the example session: fit the seed's 11 parameters, see where the model
# fails, add the effect diagnose names, and watch the error fall.
#   PY=.venv/bin/python examples/discover.sh [WORKDIR]      (from the repository root)
# (`python -m compgen`, not `compgen`: in bash that word is a shell builtin.)
set -euo pipefail
work=${1:-discover}
mkdir -p "$work"
cg() { "${PY:-python3}" -m compgen "$@"; }
# the R-test's own noise, 1σ per reading, µm: from the device's calibration (here the simulated
# session's). Without it nothing is named as found: the residual could only be judged
# against its own scatter. (Or set [rtest] noise_um in the machine file.)
noise=0.5

echo "== 1. fit the default model (the seed's 11 location parameters)"
cg fit --machine machines/ac-trunnion-itnc530.toml examples/seed-session.csv -o "$work/fit.json" --force

echo "== 2. where does it fail, and what would explain it?"
cg diagnose --from "$work/fit.json" --noise-um $noise

echo "== 3. add the effect diagnose names as found (significant, first, and with no rival)"
best=$(cg diagnose --from "$work/fit.json" --noise-um $noise --json | "${PY:-python3}" -c \
  'import json,sys; print(json.load(sys.stdin)["found"] or "")')
[ -n "$best" ] || { echo "nothing named as found: measure what diagnose advises, then fit again"; exit 0; }
cg fit --from "$work/fit.json" --add "$best" -o "$work/fit2.json" --force

echo "== 4. diagnose again, with before/after plots"
cg diagnose --from "$work/fit2.json" --noise-um $noise --before "$work/fit.json" --plots "$work/plots"
