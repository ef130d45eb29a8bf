"""``python -m flrjax.train``: the scanned, seed-vmapped trainer.

A run is a host loop over *chunks*. A chunk is one jitted call: ``vmap`` over seeds of a
``lax.scan`` over ``episodes_per_chunk`` lockstep episodes, each a ``lax.scan`` over the
episode's env steps (act, store, update). Between chunks the host evaluates, writes
``metrics.csv``, shows progress and checkpoints; nothing inside a chunk touches the host.

    python -m flrjax.train --env ant3leg --seeds 5    # FLR+DHRL, the tuned preset on a GPU
    python -m flrjax.train --env point4leg --seeds 2  # the quick preset on a CPU
    python -m flrjax.train --env ant4leg --seeds 5 --num-envs 16 --updates-per-step 0.0625
    python -m flrjax.train --env ant3leg --algo flr_dhrl --seeds 5 --flr-alpha 0.001,0.01,0.1

A comma-separated ``--flr-alpha``, ``--flr-eps``, ``--flr-next`` or ``--initial-episodes`` is
a *sweep*: every value (every combination, for several) trains ``--seeds`` seeds in the same
vmapped chunk, since these only scale, compare or select numbers inside it. ``--sweep`` lists
the points instead of crossing them, e.g. Fig. 5's ablations with DHRL (α = 0) in one run::

    python -m flrjax.train --env ant3leg --algo flr_dhrl --seeds 5 \
        --sweep "flr-alpha=0; flr-alpha=0.001; flr-alpha=0.01; flr-alpha=0.1; flr-eps=0.5"

Seed ``s`` of each point starts from the same key as seed ``s`` of a plain run, and each row
of ``metrics.csv`` names its point in columns of the swept fields.
"""

from flrjax.cli import CLI, main, parse_args, parse_cli
from flrjax.config import ConfigError, TrainConfig
from flrjax.presets import PRESETS
from flrjax.runner import TrainingFault, build, train
from flrjax.validation import validate

__all__ = ["CLI", "PRESETS", "ConfigError", "TrainConfig", "TrainingFault", "build", "main",
           "parse_args", "parse_cli", "train", "validate"]

if __name__ == "__main__":
    main()
