#!/usr/bin/env bash
# a 2-GPU host, one program at a time on each: GPU 0 ran experiments/results/learning_levers/
# learner_numbers/future_p then subgoal_freq60; GPU 1 these launches (A c9c43bf, B 59d8605, through
# phases.py as the command line: CLI=1; P: plain `python -m flrjax.train`) then subgoal_freq20
# J: the folder of phases.py and fill.py (here: ..); .whl: the wheels of the packages that the
# machine lacked (mujoco, mujoco-mjx, brax and their dependencies), installed to /tmp/site
# .ab/A.tar, .ab/B.tar: `git archive COMMIT flrjax pyproject.toml` of c9c43bf and 59d8605 with COMMIT_FULL
T0=$(date +%s); mkdir -p /tmp/w /tmp/r; rm -f /tmp/job.done
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
J=$PWD/.jobs
for s in A B; do rm -rf /tmp/$s && mkdir -p /tmp/$s && tar -xf .ab/$s.tar -C /tmp/$s; done
export PYTHONUNBUFFERED=1 FLRJAX_GIT_CLEAN=1
nvidia-smi --query-gpu=index,name,driver_version,memory.total --format=csv > /tmp/w/devices.txt
cat /tmp/A/COMMIT_FULL /tmp/B/COMMIT_FULL >> /tmp/w/devices.txt; nproc >> /tmp/w/devices.txt
job() {  # NAME LIMIT ARGS...: a program from /tmp/B, launch/first_chunk/exit times in NAME.times
  local name=$1 lim=$2; shift 2; local t=$(date +%s.%N)
  echo "launch $t" > /tmp/w/$name.times
  ( while [ ! -s /tmp/w/$name/metrics.csv ] || [ $(wc -l < /tmp/w/$name/metrics.csv) -lt 2 ]; do sleep 0.5; done
    echo "first_chunk $(date +%s.%N)" >> /tmp/w/$name.times ) &
  local w=$!
  echo "\$ python -m flrjax.train $* --time-limit $lim --out RUN" > /tmp/w/$name.log
  (cd /tmp/B && FLRJAX_GIT_COMMIT=$(cat COMMIT_FULL) PYTHONPATH=/tmp/site:/tmp/B \
     python3 -m flrjax.train "$@" --time-limit "$lim" --out /tmp/w/$name) >> /tmp/w/$name.log 2>&1
  echo "exit $? $(date +%s.%N)" >> /tmp/w/$name.times; kill $w 2>/dev/null
  rm -rf /tmp/w/$name/checkpoints
}
L() {  # SNAP NAME ARGS...: one launch through phases.py as the command line, marks in NAME.phases
  local s=$1 name=$2; shift 2
  echo "\$ python -m flrjax.train $*" > /tmp/w/$name.log
  (cd /tmp/$s && FLRJAX_GIT_COMMIT=$(cat COMMIT_FULL) PYTHONPATH=/tmp/site:/tmp/$s LAUNCH_T=$(date +%s.%N) \
     CLI=1 PHASES=/tmp/w/$name.phases python3 $J/phases.py "$@") >> /tmp/w/$name.log 2>&1
  echo "rc $?" >> /tmp/w/$name.phases
}
P() {  # SNAP NAME OUT ARGS...: plain `python -m flrjax.train`: seconds to OUT's next metrics row, to exit
  local s=$1 name=$2 out=$3; shift 3
  local n0=1; [ -s $out/metrics.csv ] && n0=$(wc -l < $out/metrics.csv)
  local t0=$(date +%s.%N) row=""
  (cd /tmp/$s && FLRJAX_GIT_COMMIT=$(cat COMMIT_FULL) PYTHONPATH=/tmp/site:/tmp/$s exec python3 -m flrjax.train "$@") > /tmp/w/$name.log 2>&1 &
  local pid=$!
  while kill -0 $pid 2>/dev/null; do
    if [ -z "$row" ] && [ -s $out/metrics.csv ] && [ $(wc -l < $out/metrics.csv) -gt $n0 ]; then row=$(awk "BEGIN{print $(date +%s.%N) - $t0}"); fi
    sleep 0.1; done
  wait $pid; local rc=$?; echo "$name first_row $row exit $(awk "BEGIN{print $(date +%s.%N) - $t0}") rc $rc" >> /tmp/w/plain.txt
}
( export CUDA_VISIBLE_DEVICES=0 JAX_COMPILATION_CACHE_DIR=/tmp/jaxcache0
  job future_p 720 --env ant3leg --seeds 3 --seed 9610 --preset wide --flr-alpha 0.01 --future-p 0.8,0.5,1.0 --steps 1536000 --checkpoint-every 0
  job subgoal_freq60 480 --env ant3leg --seeds 3 --seed 9610 --preset wide --flr-alpha 0.01 --subgoal-freq 60 --steps 1536000 --checkpoint-every 0
  echo "gpu0 $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt ) &
( export CUDA_VISIBLE_DEVICES=1 JAX_COMPILATION_CACHE_DIR=/tmp/jaxcache1
  L A A_cold --env ant3leg --seeds 5 --time-limit 1 --out /tmp/r/m
  (cd /tmp/A && PYTHONPATH=/tmp/site:/tmp/A python3 $J/fill.py /tmp/r/m) > /tmp/w/fill.log 2>&1
  L B B_cold --env ant3leg --seeds 5 --time-limit 1 --out /tmp/r/mb
  for k in 1 2; do
    for s in A B; do
      L $s ${s}_new$k --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/${s}new$k
      rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz && sync; L $s ${s}_resume$k --resume /tmp/r/rz --time-limit 1
      P $s ${s}_plainnew$k /tmp/r/${s}pn$k --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/${s}pn$k
      rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz && sync; P $s ${s}_plainresume$k /tmp/r/rz --resume /tmp/r/rz --time-limit 1
    done
  done
  echo "launches $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt
  job subgoal_freq20 500 --env ant3leg --seeds 3 --seed 9610 --preset wide --flr-alpha 0.01 --subgoal-freq 20 --steps 1536000 --checkpoint-every 0
  echo "gpu1 $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt ) &
wait
echo "total $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt
touch /tmp/job.done
