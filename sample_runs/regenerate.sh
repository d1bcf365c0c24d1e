#!/usr/bin/env bash
# Regenerates the sample runs: small real runs made by the CLI, sealed into one .duckdb file each.
#   bash sample_runs/regenerate.sh
set -euo pipefail
cd "$(dirname "$0")"
rm -rf base advanced nonmarkov supply-chain
tracelab play --scenario base --episodes 3 --seed 1 --run base
tracelab play --scenario advanced --episodes 3 --seed 2 --run advanced
tracelab play --scenario nonmarkov --episodes 2 --seed 3 --run nonmarkov
# a reasoning run (no board): the supply chain of rules/examples, recorded (docs/store.md, "Reasoning runs")
tracelab reason ../rules/examples/supply_chain.rules --graph ../rules/examples/supply_chain.graphml --steps 8 \
    --run supply-chain
for r in base advanced nonmarkov supply-chain; do tracelab seal "$r"; done
du -sh base advanced nonmarkov supply-chain

# a trained run (1v1 base on the spec path): its learning curve (metrics), training
# episodes and a few traced evaluation games, for the TUI and the replay; the checkpoint (the replay
# buffer) and the best evaluation's policy are dropped, the final policy kept. Its 30 traced evaluation
# games record the policy's decisions (Q-values, ε; the TUI's decision panel, the replay's action values)
# and every sample run records the reward by term. The README's and docs/tui.md's training and decision
# pictures are of this run (`tracelab tui --screenshots docs/images`).
rm -rf base-train
# seed 1: the plain learner wins or fails per seed (docs/training.md "Ten seeds"); seed 1 learns, seed 0 does not
tracelab train --scenario base --total-timesteps 150000 --reward-scale 0.01 --seed 1 --eval-every 20000 --eval-games 100 \
    --trace-eval-games 3 --log-every 2000 --checkpoint-every 0 --run base-train
rm -rf base-train/checkpoint base-train/policy-best
tracelab seal base-train
du -sh base-train
