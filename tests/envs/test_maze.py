import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flrjax.envs.maze import U_MAZE, Maze, ROOM_24x8


def test_u_maze_matches_reference_coordinates():
    maze = Maze(U_MAZE)
    # dhrl_official: ant starts at the origin, evaluation goal (0, 16), free space [-4, 20]^2.
    np.testing.assert_allclose(maze.start, [0, 0])
    np.testing.assert_allclose(maze.goal, [0, 16])
    lo, hi = maze.bounds
    np.testing.assert_allclose(lo, [-4, -4])
    np.testing.assert_allclose(hi, [20, 20])


def test_room_is_24_by_8_start_left_goal_right():
    maze = Maze(ROOM_24x8)
    lo, hi = maze.bounds
    np.testing.assert_allclose(hi - lo, [24, 8])
    assert maze.goal[0] - maze.start[0] == 16 and maze.goal[1] == maze.start[1]


@pytest.mark.parametrize("layout", [U_MAZE, ROOM_24x8])
def test_wall_boxes_cover_exactly_the_wall_cells(layout):
    maze = Maze(layout)
    boxes = maze.wall_boxes()
    assert len(boxes) < maze.grid.sum()  # merged
    rows, cols = maze.grid.shape
    for i in range(rows):
        for j in range(cols):
            c = maze.cell_center(i, j)
            inside = [np.all(np.abs(c - bc) < bh) for bc, bh in boxes]
            assert sum(inside) == int(maze.grid[i, j]), (i, j)


def test_sampled_goals_are_free_and_spread_like_the_reference():
    maze = Maze(U_MAZE)
    goals = jax.vmap(maze.sample_goal)(jax.random.split(jax.random.PRNGKey(0), 20000))
    g = np.asarray(goals)
    assert np.asarray(maze.is_free(goals)).all()
    # reference rand_goal: uniform on [-4, 20]^2 minus x < 12, 4 < y < 12
    assert g.min() >= -4 and g.max() <= 20
    assert not np.any((g[:, 0] < 12) & (g[:, 1] > 4) & (g[:, 1] < 12))
    # uniform over 7 equal cells: the inner corridor cell (x in 12..20, y in 4..12) gets 1/7
    frac = np.mean((g[:, 0] > 12) & (g[:, 1] > 4) & (g[:, 1] < 12))
    assert abs(frac - 1 / 7) < 0.01


def test_is_free_on_hand_points():
    maze = Maze(U_MAZE)
    pts = jnp.array([[0.0, 0.0], [0.0, 8.0], [16.0, 8.0], [-5.0, 0.0], [0.0, 16.0], [30.0, 0.0]])
    np.testing.assert_array_equal(maze.is_free(pts), [True, False, True, False, True, False])


def test_bad_layouts_raise():
    with pytest.raises(ValueError, match="equal length"):
        Maze(("###", "#S.G#"))
    with pytest.raises(ValueError, match="exactly one 'G'"):
        Maze(("#####", "#S..#", "#####"))
    with pytest.raises(ValueError, match="may only use"):
        Maze(("#####", "#S?G#", "#####"))


def test_outer_walls_and_inner_boxes():
    maze = Maze(U_MAZE)
    inner, outer = maze.split_wall_boxes()
    assert len(inner) == 1 and len(inner) + len(outer) == len(maze.wall_boxes())
    np.testing.assert_allclose(inner[0][0] - inner[0][1], [-4, 4])  # x in [-4, 12], y in [4, 12]
    np.testing.assert_allclose(inner[0][0] + inner[0][1], [12, 12])
    assert Maze(ROOM_24x8).split_wall_boxes()[0] == []
    # every free cell centre is on the inner side of every outer face
    for point, normal in maze.outer_walls():
        assert np.all((maze.free_cells - point) @ normal > 0)


def test_goals_near_the_start_are_free_and_within_the_radius():
    maze = Maze(U_MAZE)
    g = jax.vmap(lambda k: maze.sample_goal_near(k, jnp.zeros(2), 5.0))(
        jax.random.split(jax.random.PRNGKey(0), 2000))
    assert np.asarray(maze.is_free(g)).all()
    d = np.linalg.norm(np.asarray(g), axis=-1)
    assert d.max() <= 5.0 and np.median(d) > 2.5  # spread over the disc, not at the centre
