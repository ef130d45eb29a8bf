#!/usr/bin/env bash
# The README's main command, three launches in a row on one GPU with its own compilation
# cache: the first on an empty cache (cold), then twice warm, each a new run of one chunk.
export CUDA_VISIBLE_DEVICES=1 JAX_COMPILATION_CACHE_DIR=/tmp/jc1
for k in cold warm1 warm2; do
  python -m flrjax.train --env ant3leg --seeds 5 --steps 76800 --time-limit 600 --out "runs/$k" \
    > "$k.log" 2>&1
done
