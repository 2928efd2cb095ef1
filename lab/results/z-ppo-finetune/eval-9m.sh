#!/bin/bash
# A fresh set (9M, used by nothing before): the fine-tunes' best validated policies and the
# 12-round students they started from (last round), 50 episodes per seed, mean action.
L=/tmp/cp-learner
for s in 1 2 3; do
  nice -n 5 $L policy eval --checkpoint runs/z-ppo-ftc-s$s/checkpoint.json --episodes 50 --seed 9000000 --json runs/z-ppo-ftc-s$s/eval-9000000-best.json > runs/z-ppo-ftc-s$s/eval-9000000-best.txt 2>&1 &
done
wait
for s in 1 2 3; do
  nice -n 5 $L policy eval --checkpoint runs/learned-student12-s$s/checkpoint.json --last --episodes 50 --seed 9000000 --json runs/learned-student12-s$s/eval-9000000-mean.json > runs/learned-student12-s$s/eval-9000000-mean.txt 2>&1 &
done
wait
