"""Agents: the low-level goal-conditioned TD3 of DHRL (:mod:`flrjax.agents.gc_td3`)."""

from flrjax.agents import gc_td3

__all__ = ["gc_td3"]
