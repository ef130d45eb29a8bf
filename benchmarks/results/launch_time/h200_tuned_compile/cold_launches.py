"""Cold launches of the main command, each a fresh process on an empty compilation cache, one
per variant: ``NAME=XLA_FLAGS`` (flags joined by ','); a name starting with ``old`` runs a
copy of this tree in /tmp/old whose flrjax/runner.py is .jobs/runner_old.py
(``git show 9af136f:flrjax/runner.py``; ``new``: 9af136f with the chunk's compile started
right after its export, the obs-norm carry still weakly typed). Writes each launch's
timestamped log to $OUT/cold.log and prints a table: seconds from launch to the first
``jit(call)`` compile, the whole process, the trainer's wall_time and chunk_s per row
(seed 0), summed XLA compile seconds, and the three longest compiles (seconds, finished at).
Run as (one H200)::

    L=--xla_gpu_enable_llvm_module_compilation_parallelism=true A=--xla_gpu_autotune_level=0
    python cold_launches.py "base=;llvm=$L;at0=$A;base2=;both=$L,$A" 230400 455  # 9af136f
    python cold_launches.py "new=;old=;new2=;old2=" 153600 430  # prefetch_order.log
"""

import csv
import os
import re
import subprocess
import sys
import time

OUT = os.environ["OUT"]
VARIANTS = [v.split("=", 1) for v in sys.argv[1].split(";")]
STEPS = sys.argv[2] if len(sys.argv) > 2 else "230400"
DEADLINE = float(sys.argv[3]) if len(sys.argv) > 3 else 470  # no new launch after it (s)
COMPILED = re.compile(r"Finished XLA compilation of jit\((\S+)\) in ([\d.e-]+) s")
t_start = time.time()
table = []
log = open(os.path.join(OUT, "cold.log"), "w")
for name, flags in VARIANTS:
    if time.time() - t_start > DEADLINE:
        print("skip", name, flush=True)
        continue
    env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": f"/tmp/c_{name}", "JAX_LOG_COMPILES": "1",
           "XLA_FLAGS": flags.replace(",", " ")}
    out = f"/tmp/r_{name}"
    cwd = os.getcwd()
    if name.startswith("old"):
        if not os.path.exists("/tmp/old"):
            subprocess.run(["cp", "-r", cwd, "/tmp/old"], check=True)
            subprocess.run(["cp", ".jobs/runner_old.py", "/tmp/old/flrjax/runner.py"], check=True)
        cwd = "/tmp/old"
    env["PYTHONPATH"] = os.pathsep.join([p for p in env.get("PYTHONPATH", "").split(os.pathsep)
                                         if p and os.path.abspath(p) != os.getcwd()] + [cwd])
    cmd = [sys.executable, "-m", "flrjax.train", "--env", "ant3leg", "--seeds", "5",
           "--steps", STEPS, "--checkpoint-every", "0", "--out", out]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         env=env, cwd=cwd)
    lines = [(time.perf_counter() - t0, line.rstrip()) for line in p.stdout]
    p.wait()
    total = time.perf_counter() - t0
    log.write(f"== {name} XLA_FLAGS={env['XLA_FLAGS']!r} rc={p.returncode} total={total:.1f}\n")
    for t, line in lines:
        if not any(s in line for s in ("Finished tracing", "Persistent", "Not writing")):
            log.write(f"{t:7.1f} {line[:300]}\n")
    log.flush()
    comp = [(m[1], float(m[2]), t) for t, line in lines if (m := COMPILED.search(line))]
    rows = [r for r in csv.DictReader(open(os.path.join(out, "metrics.csv")))
            if r["seed"] == "0"] if p.returncode == 0 else []
    call0 = next((round(t, 1) for t, line in lines if "Compiling jit(call)" in line), None)
    big = sorted(comp, key=lambda c: -c[1])[:3]
    table.append((name, p.returncode, call0, round(total, 1),
                  [round(float(r["wall_time"]), 1) for r in rows],
                  [round(float(r["chunk_s"]), 1) for r in rows],
                  round(sum(c[1] for c in comp), 1), [(round(c[1], 1), round(c[2], 1))
                                                      for c in big]))
    print(table[-1], flush=True)
print("\nvariant rc first_call_compile_s total_s row_wall_times chunk_s sum_compile_s "
      "top3(compile_s, finished_at_s)")
for r in table:
    print(*r)
