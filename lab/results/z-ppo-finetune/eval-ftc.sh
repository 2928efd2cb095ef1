#!/bin/bash
# The critic fine-tunes (configs/policy/z_ppo_finetune_critic.toml, Adam 1e-5, KL stop 0.01):
# set 8M (the students' fresh set), 50 episodes per seed, mean action.
# Headline, set before the runs ended: the best validated policy (policy eval's default, chosen
# on validation seeds 2 000 000+); the last policy also reported.
L=cp-learner
cp target/release/learner /tmp/$L
for s in 1 2 3; do (
  while pgrep -f "out runs/z-ppo-ftc-s$s$" > /dev/null; do sleep 10; done
  nice -n 5 /tmp/$L policy eval --checkpoint runs/z-ppo-ftc-s$s/checkpoint.json --episodes 50 --seed 8000000 --json runs/z-ppo-ftc-s$s/eval-8000000-best.json > runs/z-ppo-ftc-s$s/eval-8000000-best.txt 2>&1
  nice -n 5 /tmp/$L policy eval --checkpoint runs/z-ppo-ftc-s$s/checkpoint.json --last --episodes 50 --seed 8000000 --json runs/z-ppo-ftc-s$s/eval-8000000-last.json > runs/z-ppo-ftc-s$s/eval-8000000-last.txt 2>&1
  ) &
done
wait
