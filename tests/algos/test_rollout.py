"""The rollout driver: its scans equal hand-rolled Python loops over the same callables (a toy
env and toy policies whose numbers are small integers, so float32 sums are exact)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import State

from flrjax.algos import rollout

E, T = 3, 8  # envs, env steps per episode


class Walk:
    """A toy env: the position moves by the action; success within 1 of the goal."""

    def step(self, s: State, a: jax.Array) -> State:
        xy = s.info["achieved_goal"] + a
        dist = jnp.linalg.norm(s.info["goal"] - xy)
        return s.replace(obs=xy, info={**s.info, "achieved_goal": xy, "goal_distance": dist,
                                       "success": dist <= 1.0})


def _start(n: int) -> State:
    xy = jnp.stack([jnp.arange(n, dtype=jnp.float32), jnp.zeros(n)], -1)
    goal = jnp.full((n, 2), 6.0)
    info = {"achieved_goal": xy, "goal": goal, "fallen": jnp.zeros(n, bool),
            "torso_z": jnp.ones(n), "goal_distance": jnp.linalg.norm(goal - xy, axis=-1),
            "success": jnp.zeros(n, bool)}
    return State(pipeline_state=None, obs=xy, reward=jnp.zeros(n), done=jnp.zeros(n),
                 info=info)


def _towards(goal: jax.Array, xy: jax.Array) -> jax.Array:
    return jnp.sign(goal - xy)


def test_train_in_groups_equals_a_loop():
    """No high level: each step adds its time to the carry, each group counts itself."""
    def step(c, t):
        total, groups = c
        return (total + t, groups), ({"t": t.astype(jnp.float32)}, 2 * t)

    def after(c):
        total, groups = c
        return (total, groups + 1), {"groups": groups + 1}

    (total, groups), m = rollout.train(step, after, (jnp.int32(0), jnp.int32(0)), T, 4)
    assert (int(total), int(groups)) == (sum(range(T)), T // 4)
    np.testing.assert_array_equal(m["t"], [np.mean(range(g * 4, g * 4 + 4)) for g in range(T // 4)])
    np.testing.assert_array_equal(m["groups"], np.arange(1, T // 4 + 1))


def test_train_in_periods_equals_a_loop():
    """A high level: each period starts with a choice (its context), its steps see it, and its
    end reads the period's group metrics and step outputs."""
    k, group = 4, 2

    def choose(c, p):
        return (c, 0), 100 * p

    def step(c, t):
        total, seen = c
        return (total + t, seen + 1), ({"t": t.astype(jnp.float32)}, t)

    def finish(c, low, context, p, m, out):
        total, seen = low
        return total + context, {"context": context, "seen": seen, "mean_t": m["t"].mean(),
                                 "out": out.reshape(-1)}

    total, m = rollout.train(step, lambda c: (c, {}), jnp.int32(0), T, group,
                             rollout.High(k, choose, finish))
    expect_total, rows = 0, []
    for p in range(T // k):
        ts = list(range(p * k, (p + 1) * k))
        expect_total += sum(ts) + 100 * p
        rows.append((100 * p, k, np.mean(ts), ts))
    assert int(total) == expect_total
    np.testing.assert_array_equal(m["context"], [r[0] for r in rows])
    np.testing.assert_array_equal(m["seen"], [r[1] for r in rows])
    np.testing.assert_array_equal(m["mean_t"], [r[2] for r in rows])
    np.testing.assert_array_equal(m["out"], [r[3] for r in rows])


def _loop(env: Walk, s: State, policy, steps: int, xs, memory):
    outs, recs = [], []
    for i in range(steps):
        memory, d = policy(memory, s, None if xs is None else xs[i])
        outs.append(d.out)
        recs.append(rollout.trace_step(s, d.target, d.subgoal))
        s = jax.vmap(env.step)(s, d.action)
    return s, outs, recs


def test_unroll_equals_a_loop_and_traces_each_step():
    """A policy with memory (steps taken) and a scanned input (a push on every other step)."""
    env, s0 = Walk(), _start(E)

    def policy(count, s, push):
        goal = s.info["goal"]
        a = _towards(goal, s.info["achieved_goal"]) + push
        return count + 1, rollout.Decision(a, goal, goal, count)

    xs = jnp.tile(jnp.asarray([0.0, 1.0]), T // 2)
    s, out, rec = rollout.unroll(env, s0, policy, T, xs=xs, memory=jnp.int32(0), trace=True)
    s_loop, outs, recs = _loop(env, s0, policy, T, xs, jnp.int32(0))
    np.testing.assert_array_equal(s.obs, s_loop.obs)
    np.testing.assert_array_equal(out, outs)
    for name in ("xy", "waypoint", "subgoal"):
        np.testing.assert_array_equal(rec[name], np.stack([r[name] for r in recs]))
    metrics, trace = rollout.report(s, 2, rec, True, {"eval/extra": jnp.float32(1)})
    assert trace["xy"].shape == (2, T, 2)
    np.testing.assert_array_equal(trace["xy"][1], np.stack([r["xy"][1] for r in recs]))
    np.testing.assert_array_equal(metrics["eval/success_rate"], s_loop.info["success"][:2].mean())
    assert float(metrics["eval/extra"]) == 1.0


def test_unroll_periods_replans_at_each_period_start():
    """The high level picks a subgoal 2 steps ahead at each period's start; the low level walks
    to it; each period's plan reports where it started."""
    env, s0, k = Walk(), _start(E), 4

    def plan(s):
        subgoal = s.info["achieved_goal"] + 2.0

        def policy(memory, s, _):
            a = _towards(subgoal, s.info["achieved_goal"])
            return memory, rollout.Decision(a, subgoal, subgoal)

        return policy, None, None, s.info["achieved_goal"].sum()

    s, (starts, _), rec = rollout.unroll_periods(env, s0, plan, T, k, trace=True)
    s_loop, expect_starts, expect_xy = s0, [], []
    for _ in range(T // k):
        policy, memory, xs, out = plan(s_loop)
        expect_starts.append(out)
        s_loop, _, recs = _loop(env, s_loop, policy, k, xs, memory)
        expect_xy += [r["xy"] for r in recs]
    np.testing.assert_array_equal(s.obs, s_loop.obs)
    np.testing.assert_array_equal(starts, expect_starts)
    _, trace = rollout.traced({}, rec, s, E)
    np.testing.assert_array_equal(trace["xy"], np.stack(expect_xy, 1))
