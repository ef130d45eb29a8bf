"""Seconds from launch of each warm launch of the main command, from the phase marks that
phases.py appended (python phases.py ARGS runs `python -m flrjax.train ARGS` with them):
imports done, the CLI's parse done (the env built), the restore's start and end, the first
chunk called; then the seconds of that call spent loading programs that were still loading
in background threads (the trainer's "first chunk: ..., N s of it tracing and compiling (or
loading compiled programs)" line), their sum (when the first chunk's training began) and
the first chunk's end. profile_175e392/: the profile before the change (resume_z: the checkpoint
as saved, zstd; resume_u: rewritten without compression; *_warm: jax.devices() in a thread
from the start); before_after/: 175e392 (A) and e3d3ae5 (B) on one machine (*_warm2: a
first tiny program in a thread right after JAX's import, as flrjax's command line
starts one since 0332c57); backend_thread/: c9c43bf (A, before it) and 59d8605 (B) on GPU 1 of a
2-GPU host whose GPU 0 trained meanwhile, through phases.py as the command line (CLI=1), and
plain launches without marks (plain.txt: seconds to the run's next metrics row and to exit).

    python benchmarks/results/launch_time/h200_launch/table.py
"""
import glob
import os
import re

HERE = os.path.dirname(os.path.abspath(__file__))
COLUMNS = {"import flrjax": "imports", "parse_cli end #1": "parsed",
           "restore start #1": "restore from", "restore end #1": "restore to",
           "first chunk call": "first chunk called"}


def marks(path: str) -> dict[str, float]:
    out = {}
    with open(path) as f:
        for line in f:
            t, _, name = line.strip().partition(" ")
            try:
                out.setdefault(name, float(t))
            except ValueError:
                pass
    return out


def loading(log: str) -> float | None:
    """The first chunk's seconds of tracing, compiling or loading, from the trainer's line."""
    with open(log) as f:
        m = re.search(r"first chunk: \d+ s, (\d+) s of it", f.read())
    return float(m.group(1)) if m else None


def main() -> None:
    for folder in ("profile_175e392", "before_after", "backend_thread"):
        print(f"{folder}: seconds from launch")
        print(f"{'launch':<16}" + "".join(f"{c:>20}" for c in COLUMNS.values())
              + f"{'loading in it':>15}{'training from':>15}{'first chunk done':>18}")
        for path in sorted(glob.glob(os.path.join(HERE, folder, "*.phases"))):
            name = os.path.basename(path)[:-len(".phases")]
            if "cold" in name:
                continue
            m = marks(path)
            load = loading(path[:-len(".phases")] + ".log")
            print(f"{name:<16}" + "".join(f"{m[k]:>20.2f}" if k in m else f"{'-':>20}"
                                          for k in COLUMNS)
                  + f"{load:>15.0f}{m['first chunk call'] + load:>15.1f}"
                  + f"{m['first chunk done']:>18.2f}")
        plain = os.path.join(HERE, folder, "plain.txt")
        if os.path.exists(plain):
            with open(plain) as f:
                print("plain launches: seconds to the next metrics row / to exit\n" + "".join(
                    f"{w[0]:<16}{float(w[2]):>8.2f} /{float(w[4]):>6.2f}\n"
                    for w in sorted(line.split() for line in f)), end="")
        print()


if __name__ == "__main__":
    main()
