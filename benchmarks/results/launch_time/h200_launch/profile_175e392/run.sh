#!/usr/bin/env bash
# warm launches of the main command with phase marks: new runs, resumes of a full-size checkpoint
# J: the folder of phases.py and fill.py (here: ..); .whl: the wheels of the packages that the
# machine lacked (mujoco, mujoco-mjx, brax and their dependencies), installed to /tmp/site
# .snap: `git archive 175e392` with COMMIT_FULL
T0=$(date +%s); mkdir -p /tmp/w; rm -f /tmp/job.done
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
J=$PWD/.jobs
rm -rf /tmp/snap && cp -r .snap /tmp/snap && cd /tmp/snap
export FLRJAX_GIT_COMMIT=$(cat /tmp/snap/COMMIT_FULL) FLRJAX_GIT_CLEAN=1
export PYTHONPATH=/tmp/site:/tmp/snap PYTHONUNBUFFERED=1 JAX_COMPILATION_CACHE_DIR=/tmp/jaxcache
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > /tmp/w/devices.txt
nproc >> /tmp/w/devices.txt
L() {  # NAME ARGS...: one launch, its phases in /tmp/w/NAME.phases
  local name=$1; shift
  echo "\$ python -m flrjax.train $*" > /tmp/w/$name.log
  LAUNCH_T=$(date +%s.%N) PHASES=/tmp/w/$name.phases python3 $J/phases.py "$@" >> /tmp/w/$name.log 2>&1
  echo "rc $?" >> /tmp/w/$name.phases
}
L cold --env ant3leg --seeds 5 --time-limit 1 --out /tmp/r/m
python3 $J/fill.py /tmp/r/m --uncompressed > /tmp/w/fill.log 2>&1
for k in 1 2; do
  L new$k --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/new$k
  rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz; L resume_z$k --resume /tmp/r/rz --time-limit 1
  rm -rf /tmp/r/ru && cp -r /tmp/r/m_U /tmp/r/ru; L resume_u$k --resume /tmp/r/ru --time-limit 1
done
WARM=1 L new_warm --env ant3leg --seeds 5 --steps 76800 --out /tmp/r/new3
rm -rf /tmp/r/rz && cp -r /tmp/r/m /tmp/r/rz; WARM=1 L resume_z_warm --resume /tmp/r/rz --time-limit 1
echo "total $(( $(date +%s) - T0 ))" >> /tmp/w/devices.txt
touch /tmp/job.done
