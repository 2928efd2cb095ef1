#!/bin/bash
# The critic fine-tunes' best validated policies with the box also turned (±0.26 rad), set 9M.
L=/tmp/cp-learner
for s in 1 2 3; do
  $L policy eval --checkpoint runs/z-ppo-ftc-s$s/checkpoint.json --episodes 50 --seed 9000000 --set env.world.task.box_yaw_range_rad=0.26 --json runs/z-ppo-ftc-s$s/eval-9000000-yaw-best.json > runs/z-ppo-ftc-s$s/eval-9000000-yaw-best.txt 2>&1 &
done
wait
