#!/bin/bash
# A third fresh set, 10M (2026-12-07), for the three critic fine-tunes, best validated policy,
# 50 episodes, mean action. Seed 3 was evaluated through the shipped package
# (artifacts/z-ppo-square), from a directory outside the repository; its first 10 episodes of
# 9M the same way, to check the package against the lab record (shipped-eval-9000000-first10.json).
L=target/release/learner
$L policy eval --checkpoint artifacts/z-ppo-square/checkpoint.json --episodes 50 --seed 10000000 \
    --json lab/results/z-ppo-finetune/critic-frozen-s3/eval-10000000-best.json
$L policy eval --checkpoint artifacts/z-ppo-square/checkpoint.json --episodes 10 --seed 9000000 \
    --json lab/results/z-ppo-finetune/critic-frozen-s3/shipped-eval-9000000-first10.json
for s in 1 2; do
  nice -n 10 $L policy eval --checkpoint lab/results/z-ppo-finetune/critic-frozen-s$s/checkpoint.json \
      --episodes 50 --seed 10000000 --json lab/results/z-ppo-finetune/critic-frozen-s$s/eval-10000000-best.json
done
