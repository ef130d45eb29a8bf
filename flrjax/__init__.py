"""flrjax: hierarchical goal-conditioned RL with the forward-looking reward, in JAX/MJX."""

__version__ = "0.1.0"
