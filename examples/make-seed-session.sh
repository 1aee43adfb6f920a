#!/usr/bin/env bash
# Regenerates seed-session.csv: K4, K1, K2 on the seed machine with the errors in
# truth-seed-session.json and 0.5 µm white noise. Run from the repository root with the
# project's venv: `PY=.venv/bin/python examples/make-seed-session.sh [OUTPUT.csv]`.
# (Not `compgen …`: in bash that word is a shell builtin, which wins over PATH.)
set -euo pipefail
"${PY:-python3}" -m compgen simulate --machine machines/ac-trunnion-itnc530.toml \
  --truth examples/truth-seed-session.json --paths K4,K1,K2 \
  --noise-um 0.5 --seed 2026 -o "${1:-examples/seed-session.csv}" --force
