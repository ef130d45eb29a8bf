#!/usr/bin/env bash
# before (A) / after (B) on one machine: warm launches of the main command with phase marks
# J: the folder of phases.py and fill.py (here: ..); .whl: the wheels of the packages that the
# machine lacked (mujoco, mujoco-mjx, brax and their dependencies), installed to /tmp/site
# .ab/A.tar, .ab/B.tar: `git archive COMMIT flrjax pyproject.toml` of 175e392 and e3d3ae5 with COMMIT_FULL
T0=$(date +%s); mkdir -p /tmp/w /tmp/r; rm -f /tmp/job.done
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
J=$PWD/.jobs
for s in A B; do rm -rf /tmp/$s && mkdir -p /tmp/$s && tar -xf .ab/$s.tar -C /tmp/$s; done
export PYTHONUNBUFFERED=1 JAX_COMPILATION_CACHE_DIR=/tmp/jaxcache FLRJAX_GIT_CLEAN=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > /tmp/w/devices.txt
cat /tmp/A/COMMIT_FULL /tmp/B/COMMIT_FULL >> /tmp/w/devices.txt
L() {  # SNAP NAME ARGS...: one launch from /tmp/SNAP, its phases in /tmp/w/NAME.phases
  local s=$1 name=$2; shift 2
  echo "\$ python -m flrjax.train $*" > /tmp/w/$name.log
  (cd /tmp/$s && FLRJAX_GIT_COMMIT=$(cat COMMIT_FULL) PYTHONPATH=/tmp/site:/tmp/$s LAUNCH_T=$(date +%s.%N) \
     PHASES=/tmp/w/$name.phases python3 $J/phases.py "$@") >> /tmp/w/$name.log 2>&1
  echo "rc $?" >> /tmp/w/$name.phases
}
L A A_cold --env ant3leg --seeds 5 --time-limit 1 --out /tmp/r/m
(cd /tmp/A && PYTHONPATH=/tmp/site:/tmp/A python3 $J/fill.py /tmp/r/m) > /tmp/w/fill.log 2>&1
L B B_cold --env ant3leg --seeds 5 --time-limit 1 --out /tmp/r/mb
for k in 1 2; do
  for s in A B; do
    L $s ${s}_new$k --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/${s}new$k
    rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz && sync; L $s ${s}_resume$k --resume /tmp/r/rz --time-limit 1
  done
done
rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz && sync; WARM=2 L B B_resume_warm2 --resume /tmp/r/rz --time-limit 1
WARM=2 L B B_new_warm2 --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/Bnew3
echo "total $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt
touch /tmp/job.done
