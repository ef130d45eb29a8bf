"""Training algorithms, each a set of pure per-seed functions the trainer vmaps and scans, with
its config dataclass and its translation from the run's flags (``from_run``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from flrjax.agents import gc_td3

if TYPE_CHECKING:
    from flrjax.config import TrainConfig


def td3_config(run: TrainConfig) -> gc_td3.TD3Config:
    """The goal-conditioned TD3 of the run's learner flags (network width, batch, targets)."""
    return gc_td3.TD3Config(hidden_sizes=(run.hidden,) * 3, batch_size=run.batch_size,
                            polyak=run.polyak, target_update_freq=run.target_update_freq)
