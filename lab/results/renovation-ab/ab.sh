#!/bin/bash
# Alternating rounds, base (306b4b7, before the renovation) vs new (HEAD).
R=${1:-3}; OUT=/tmp/ab/ab306.jsonl; : > $OUT; : > /tmp/ab/ab306-control.txt
for r in $(seq 1 $R); do
  if [ $((r % 2)) = 1 ]; then order="base new"; else order="new base"; fi
  for side in $order; do
    if [ $side = base ]; then dir=/tmp/base306/rt-controller; cs=/tmp/ab/control_step-base306; rb=/tmp/ab/repr_bench-base306;
    else dir=/work/main/rt-controller; cs=/tmp/ab/control_step-new2; rb=/tmp/ab/repr_bench-new2; fi
    (cd $dir && $cs --bench --warm-up-time 1 --measurement-time 4 --noplot 2>/dev/null | grep -E "^control_(step|cycle)/|time:|single-step" | tr -s ' ' | sed "s/^/$side r$r /") >> /tmp/ab/ab306-control.txt
    t=$(RAYON_NUM_THREADS=2 $rb train 64 5)
    i=$(RAYON_NUM_THREADS=1 $rb infer-fast 1 200)
    echo "{\"round\": $r, \"side\": \"$side\", \"train\": $t, \"infer\": $i}" | tee -a $OUT
  done
done
