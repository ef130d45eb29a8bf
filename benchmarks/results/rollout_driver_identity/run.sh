#!/bin/bash
# The fixed-seed CPU runs this comparison reads: every method, and an alpha sweep, of the
# checkout TREE, into OUT/<name>/ (compare OUT/<name>/metrics.csv of two trees with compare.py).
# usage: run.sh TREE OUT
set -e
cd "$1"
flags=(--env point3leg --preset quick --steps 3200 --no-compile-cache)
for a in flat dhrl flr_dhrl pig flr_pig higl; do
  PYTHONPATH=$PWD python -m flrjax.train "${flags[@]}" --algo "$a" --out "$2/$a" > "$2/$a.log" 2>&1
done
PYTHONPATH=$PWD python -m flrjax.train "${flags[@]}" --algo flr_dhrl --flr-alpha 0,0.01 \
  --seeds 2 --out "$2/alpha" > "$2/alpha.log" 2>&1
