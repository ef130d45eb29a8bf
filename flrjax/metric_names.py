"""Metric names. A method names each metric it reports ``namespace/name``, the namespace
saying what produced it, so that code that treats metrics differently asks the namespace,
never the name:

- ``low/`` and ``high/``: the low and the high level's learners (losses, Q, their batches'
  reward); ``aux/``: a method's other learned networks (e.g. HIGL's adjacency and novelty
  networks). All of :data:`LEARNERS` must stay finite: the trainer stops a run where one
  does not.
- ``stats/``: what the chunk's episodes and batches show (training success, physics resets,
  the landmark graph, the FLR reward's statistics, the graph's and the subgoals' quality
  against the maze's true path lengths), NaN where the chunk had no data for it.
- ``eval/``: the evaluation's.

metrics.csv keeps the flat column names it had before the namespaces (:func:`column`).
"""

from __future__ import annotations

#: Namespaces of learners' metrics: every one must be finite.
LEARNERS = ("low", "high", "aux")
NAMESPACES = (*LEARNERS, "stats", "eval")

#: metrics.csv's columns that time a run rather than measure what it learned (two runs of the
#: same numbers differ in them): seconds since launch, env steps per second of the chunk with
#: its evaluation, and the seconds of each (the first chunk's and evaluation's include compiling).
TIMES = ("wall_time", "env_steps_per_s", "chunk_s", "eval_s")

#: Columns named before the namespaces that the rule of :func:`column` does not give.
_COLUMNS = {"high/landmark_loss": "landmark_loss", "eval/path_length": "eval_path_length",
            "eval/on_target_frac": "eval_on_target_frac"}


def scoped(namespace: str, metrics: dict) -> dict:
    """``metrics`` with their names in ``namespace``."""
    return {f"{namespace}/{k}": v for k, v in metrics.items()}


def namespace(name: str) -> str:
    """The namespace of ``name``; a :class:`ValueError` if it has none of :data:`NAMESPACES`."""
    space, sep, _ = name.partition("/")
    if not sep or space not in NAMESPACES:
        raise ValueError(f"metric {name!r} is not named namespace/name with a namespace of "
                         f"{', '.join(NAMESPACES)}")
    return space


def is_learner(name: str) -> bool:
    """Whether ``name`` is a learner's metric (:data:`LEARNERS`)."""
    return namespace(name) in LEARNERS


def column(name: str) -> str:
    """metrics.csv's column of the metric ``name``: the name without its namespace, with
    ``high_`` before the high level's (``high/q`` -> ``high_q``), but for :data:`_COLUMNS`."""
    space = namespace(name)
    short = name.partition("/")[2]
    return _COLUMNS.get(name, f"high_{short}" if space == "high" else short)


def columns(metrics: dict) -> dict:
    """``metrics`` by their columns (:func:`column`), in the columns' alphabetical order (as
    metrics.csv has always had them); a :class:`ValueError` if two share a column."""
    out = {column(k): v for k, v in metrics.items()}
    if len(out) < len(metrics):
        raise ValueError(f"metrics {sorted(metrics)} share a column")
    return dict(sorted(out.items()))
