#!/usr/bin/env bash
# Regenerates the replay screenshots of README.md and docs/replay.md with rerun's own viewer, rendered
# without a GPU (Vulkan on llvmpipe, about 20 s a picture on 2 cores):
#   apt-get install -y mesa-vulkan-drivers xvfb
#   bash docs/images/regenerate.sh
# Every picture is of a real run: the sample runs (sample_runs/regenerate.sh, the supply-chain reasoning
# included) and games of specs played here.
set -euo pipefail
cd "$(dirname "$0")/../.."
tmp=$(mktemp -d)
# X puts the pointer at the screen's centre: the screen is more than twice the window's 3600x2200 pixels
# (1800x1100 points at 2x, placed at the top left) so the pointer is off the window and no hover tooltip
# lands on a view (at 4000x2400 one sat over the rule log).
Xvfb :97 -screen 0 7400x4600x24 >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb; rm -rf "$tmp"' EXIT
sleep 2

# shot RRD PNG: the viewer at 1800x1100 points (it renders at 2x), halved to 1800x1100 pixels and cut to
# 256 colours (the viewer's flat colours and grey text look the same; the graph's picture was 1.2 MB, 0.24 MB so)
shot() {
  DISPLAY=:97 rerun "$(realpath "$1")" --screenshot-to "$tmp/shot.png" --window-size 1800x1100 >/dev/null 2>&1
  python -c 'import sys; from PIL import Image; im = Image.open(sys.argv[1]).convert("RGB")
im = im.resize((im.width // 2, im.height // 2), Image.LANCZOS)
im.quantize(256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).save(sys.argv[2], optimize=True)' \
    "$tmp/shot.png" "$2"
}

# README and the top of docs/replay.md: a hit, a death, the end of the game and their why-trees
tracelab replay sample_runs/advanced --episode 2 --open-at end --save "$tmp/kill.rrd"
shot "$tmp/kill.rrd" docs/images/replay.png

# the non-Markov sample: 2v2 with slow agents
tracelab replay sample_runs/nonmarkov --episode 0 --open-at end --save "$tmp/2v2.rrd"
shot "$tmp/2v2.rrd" docs/images/replay-2v2.png

# the trained sample's first traced evaluation game (episode 776): the policy's value of each action per
# step and the return by reward term, stacked under the return, beside the board
tracelab replay sample_runs/base-train --episode 776 --open-at end --save "$tmp/values.rrd"
shot "$tmp/values.rrd" docs/images/replay-values.png

# a game played here through the spec path: the advanced rules at two a team (war_advanced_2v2.toml)
tracelab play --env rules/gridworld/war_advanced_2v2.toml --episodes 1 --seed 3 --run "$tmp/a2v2" >/dev/null
tracelab replay "$tmp/a2v2" --episode 0 --open-at end --save "$tmp/a2v2.rrd"
shot "$tmp/a2v2.rrd" docs/images/replay-advanced-2v2.png
# a world of docs/worlds.md's kind with a board: the trap corridor, its agent dying a step after the trap
tracelab play --env rules/examples/trap_corridor.toml --episodes 2 --seed 1 --run "$tmp/trap" >/dev/null
tracelab replay "$tmp/trap" --episode 1 --open-at end --save "$tmp/trap.rrd"
shot "$tmp/trap.rrd" docs/images/replay-spec.png
# a run without a board: the supply-chain sample's reasoning over its 2,430-node graph at its last step,
# coloured by `exposed` (the default), with the why-tree of an alert
tracelab replay sample_runs/supply-chain --open-at end --why 'alert(sam-gray)' --save "$tmp/graph.rrd"
shot "$tmp/graph.rrd" docs/images/replay-graph.png
ls -la docs/images/*.png
