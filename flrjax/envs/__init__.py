"""Environment registry: ``make(name, **overrides)`` and ``names()``.

``ant4leg`` and ``ant3leg`` are the paper's MJX ant mazes (§3.1); ``point4leg``/``point3leg``
are a pure-JAX point mass in the same two layouts, for fast tests. Overrides are fields of the
env's config dataclasses (e.g. ``episode_length=50``, ``solver_iterations=4``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from brax.envs.base import Env

from flrjax.envs.ant_maze import AntMaze, AntMazeConfig
from flrjax.envs.ant_xml import AntSpec
from flrjax.envs.maze import U_MAZE, Maze, ROOM_24x8
from flrjax.envs.point_maze import PointMaze, PointMazeConfig

__all__ = ["AntMaze", "AntMazeConfig", "AntSpec", "Maze", "PointMaze", "PointMazeConfig",
           "make", "names"]


def _split(overrides: dict, *classes: type) -> list[dict]:
    """Route each override to the dataclass that has a field of that name."""
    parts: list[dict] = [{} for _ in classes]
    valid: list[str] = []
    for i, cls in enumerate(classes):
        fields = {f.name for f in dataclasses.fields(cls)}
        valid += sorted(fields)
        for k in list(overrides):
            if k in fields:
                parts[i][k] = overrides.pop(k)
    if overrides:
        raise ValueError(f"unknown env option(s) {sorted(overrides)}; valid: {valid}")
    return parts


def _ant(n_legs: int, first_leg_deg: float, layout: tuple[str, ...]) -> Callable[..., Env]:
    def build(**overrides) -> Env:
        spec_kw, cfg_kw, maze_kw = _split(dict(overrides), AntSpec, AntMazeConfig, Maze)
        spec = AntSpec(**{"n_legs": n_legs, "first_leg_deg": first_leg_deg, **spec_kw})
        return AntMaze(spec, Maze(layout, **maze_kw), AntMazeConfig(**cfg_kw))

    return build


def _point(layout: tuple[str, ...]) -> Callable[..., Env]:
    def build(**overrides) -> Env:
        cfg_kw, maze_kw = _split(dict(overrides), PointMazeConfig, Maze)
        return PointMaze(Maze(layout, **maze_kw), PointMazeConfig(**cfg_kw))

    return build


_REGISTRY: dict[str, Callable[..., Env]] = {
    # AntMaze4leg: the HIRO/HIGL/DHRL U-maze with the standard ant (legs at 45° + k·90°).
    "ant4leg": _ant(4, 45.0, U_MAZE),
    # AntMaze3leg: a tripod (legs at 0°, 120°, 240°, one pointing at the goal) in a 24 x 8 room.
    "ant3leg": _ant(3, 0.0, ROOM_24x8),
    "point4leg": _point(U_MAZE),
    "point3leg": _point(ROOM_24x8),
}


def names() -> list[str]:
    """The registered environment names."""
    return sorted(_REGISTRY)


def make(name: str, **overrides) -> Env:
    """Build environment ``name``; unknown names or options raise ``ValueError``."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; valid: {', '.join(names())}")
    return _REGISTRY[name](**overrides)
