"""Issue 24 screen (benchmark-only monkeypatches, nothing in flrjax changes): does flattening
the Adam states / the Polyak average, or skipping the masked target update, cut the time of
one FLR+DHRL low-level update (5 seeds x batch 1024)?  'notarget' is a bound: the real skip
would still update on 1 step in 10."""
import json
import os
import sys

import jax
import optax
from jax.flatten_util import ravel_pytree

sys.path.insert(0, "benchmarks")
import low_update  # noqa: E402

from flrjax import config, runner  # noqa: E402
from flrjax.agents.gc_td3 import learner  # noqa: E402

ORIG = {k: getattr(learner, k) for k in ("_critic_tx", "_actor_tx", "_polyak", "update_targets")}


def flat_polyak(net, polyak):
    t, unravel = ravel_pytree(net.target_params)
    o, _ = ravel_pytree(net.params)
    return net.replace(target_params=unravel(polyak * t + (1.0 - polyak) * o))


PATCHES = {
    "base": {},
    "flatadam": {"_critic_tx": lambda c: optax.flatten(optax.adam(c.lr_critic)),
                 "_actor_tx": lambda c: optax.flatten(optax.adam(c.lr_actor))},
    "flatpolyak": {"_polyak": flat_polyak},
    "notarget": {"update_targets": lambda s, p: s},
}


def main():
    variants = sys.argv[1].split(",")
    algo = sys.argv[2] if len(sys.argv) > 2 else "f32"
    options = dict(runner.COMPILER_OPTIONS)
    base = config.TrainConfig(env="ant3leg", algo="dhrl", seeds=5, num_envs=1,
                              updates_per_step=1.0, batch_size=1024, hidden=256,
                              buffer_episodes=20, steps=3000, devices=1)
    cfg = low_update.variant_config(base, algo)
    out = {"device": jax.devices()[0].device_kind, "jax": jax.__version__,
           "commit": os.environ.get("FLRJAX_GIT_COMMIT"), "algo_variant": algo, "rows": {}}
    for v in variants:
        for k, f in ORIG.items():
            setattr(learner, k, f)
        for part in v.split("+"):
            for k, f in PATCHES[part].items():
                setattr(learner, k, f)
        jax.clear_caches()
        r = low_update.time_variant(cfg, 40, 0.7, 5, options)
        out["rows"][v] = r["ms_per_update"]
        print(f"{v:<28}{r['ms_per_update']:8.4f} ms/update  {r['tflops']:6.1f} TFLOP/s", flush=True)
    path = os.path.join(os.environ.get("OUT", "/tmp"), "flat_screen.json")
    with open(path, "w") as fh:
        json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
