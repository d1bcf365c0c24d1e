#!/usr/bin/env bash
# Regenerates the sample runs: small real runs made by the CLI, sealed into one .duckdb file each.
#   bash sample_runs/regenerate.sh
set -euo pipefail
cd "$(dirname "$0")"
rm -rf base advanced nonmarkov
tracelab play --scenario base --episodes 3 --seed 1 --run base
tracelab play --scenario advanced --episodes 3 --seed 2 --run advanced
tracelab play --scenario nonmarkov --episodes 2 --seed 3 --run nonmarkov
for r in base advanced nonmarkov; do tracelab seal "$r"; done
du -sh base advanced nonmarkov
