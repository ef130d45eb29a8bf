#!/usr/bin/env bash
# The README's main command as written on a fresh host of 2 H200s (empty compilation cache; the 5
# runs split over both GPUs by --devices's default), stopped by --time-limit; rows.txt: the launch
# time, then the time at which metrics.csv reached each line count (header, then 5 rows per
# evaluation), polled every 0.25 s.
echo "launch $(date +%s.%N)" > rows.txt
( n=0; while true; do
    m=$( [ -f run/metrics.csv ] && wc -l < run/metrics.csv || echo 0 )
    if [ "$m" != "$n" ]; then echo "rows $m $(date +%s.%N)" >> rows.txt; n=$m; fi; sleep 0.25; done ) &
python -m flrjax.train --env ant3leg --seeds 5 --time-limit 420 --out run > log.txt 2>&1
echo "exit $? $(date +%s.%N)" >> rows.txt; kill $!
