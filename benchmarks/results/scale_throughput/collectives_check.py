"""List the cross-device collectives in the compiled training chunk of a tiny flr_dhrl run
sharded over 4 CPU devices (a diagnostic of the multi-GPU rows in results.md).

Usage: ``python collectives_check.py [FLAGS...]`` with flrjax importable, e.g. with and without
``--flr-alpha 0,0.01`` (the settings of several GPUs: ``--flr-value-chunk 0 --value-kernel xla``).
"""

import os
import re
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from flrjax import runner  # noqa: E402
from flrjax.cli import parse_cli  # noqa: E402

TINY = ["--env", "point3leg", "--algo", "flr_dhrl", "--preset", "quick", "--hidden", "16",
        "--batch-size", "32", "--episodes-per-chunk", "1", "--initial-episodes", "4",
        "--eval-episodes", "2", "--steps", "400", "--out", "/tmp/collectives_check"]
COLLECTIVE = r" (all-gather|all-reduce|all-to-all|collective-permute|reduce-scatter)(-start)?\("


def main(flags: list[str]) -> None:
    cfg = parse_cli(TINY + flags).cfg
    init, chunk, _ = runner.build(cfg)
    carry = runner.init_carry(cfg, init, jax.random.PRNGKey(0))
    hlo = chunk.lower(carry, jnp.int32(0)).compile().as_text()
    found = [line for line in hlo.splitlines() if re.search(COLLECTIVE, line)]
    print(f"{cfg.runs} runs on {runner.num_devices(cfg)} devices: {len(found)} collectives")
    for line in found:
        op = re.search(COLLECTIVE, line).group(1)
        where = re.search(r'op_name="([^"]+)"', line)
        shapes = line.split("=", 1)[1].split(op)[0].strip()
        print(f"  {op} at {where.group(1) if where else '?'}\n    {shapes[:300]}")


if __name__ == "__main__":
    main(sys.argv[1:])
