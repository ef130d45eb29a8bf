"""The method protocol: a method defined here alone, registered, trains through the command line
with its own flag (in --help, checked, swept, saved), and the package names no method."""

from __future__ import annotations

import ast
import csv
import dataclasses
import json
import pathlib
import re

import jax
import jax.numpy as jnp
import pytest
from flax import struct

from flrjax import algos, cli, config
from flrjax.algos import rollout
from flrjax.algos.common import BaseConfig, base_fields, reset_envs
from flrjax.options import Sweepable, flag

PACKAGE = pathlib.Path(config.__file__).parent


@dataclasses.dataclass(frozen=True)
class ToyOptions:
    toy_lr: float | tuple[float, ...] = flag(
        0.5, "step size of the toy's gain; comma-separated values sweep it", "toy",
        sweep=Sweepable("toy lr"), check=(lambda v: v >= 0, ">= 0"))


@dataclasses.dataclass(frozen=True)
class ToyConfig(BaseConfig):
    lr: float | jax.Array


@struct.dataclass
class ToyCarry:
    env_state: object
    gain: jax.Array  # [action, goal] : the policy a = tanh(gain @ (goal - position))
    key: jax.Array


def _act(gain: jax.Array, s) -> jax.Array:
    return jnp.tanh((s.info["goal"] - s.info["achieved_goal"]) @ gain.T)


def _init(key, env, cfg: ToyConfig, hp) -> ToyCarry:
    k_env, k_carry = jax.random.split(key)
    return ToyCarry(reset_envs(env, k_env, cfg.num_envs), jnp.zeros((env.action_size, 2)),
                    k_carry)


def _train_episode(carry: ToyCarry, episode, env, cfg: ToyConfig):
    """Each step, ascend the alignment of the action with the direction to the goal."""
    key, k_reset = jax.random.split(carry.key)
    s0 = reset_envs(env, k_reset, cfg.num_envs)

    def alignment(gain, s):
        d = s.info["goal"] - s.info["achieved_goal"]
        d = d / (jnp.linalg.norm(d, axis=-1, keepdims=True) + 1e-6)
        return jnp.mean(jnp.sum(_act(gain, s)[:, :2] * d, axis=-1))

    def step(c, _):
        s, gain = c
        value, grad = jax.value_and_grad(alignment)(gain, s)
        s_next = jax.vmap(env.step)(s, _act(gain, s))
        return (s_next, gain + cfg.lr * grad), ({"low/toy_loss": -value}, None)

    (s, gain), m = rollout.train(step, lambda c: (c, {}), (s0, carry.gain),
                                 env.config.episode_length, 1)
    metrics = {"low/toy_loss": m["low/toy_loss"].mean(),
               "stats/train_success": s.info["success"].mean()}
    return ToyCarry(s, gain, key), metrics


def _evaluate(carry: ToyCarry, key, env, cfg: ToyConfig, trace: bool = False):
    def policy(memory, s, _):
        return memory, rollout.Decision(_act(carry.gain, s), s.info["goal"], s.info["goal"])

    s0 = rollout.start_states(env, key, cfg.eval_episodes)
    s, _, rec = rollout.unroll(env, s0, policy, env.config.episode_length, trace=trace)
    return rollout.report(s, cfg.eval_episodes, rec, trace)


TOY = algos.Method(
    name="toy", paper_name="Toy", options=ToyOptions,
    from_run=lambda run, env: ToyConfig(**base_fields(run, env), lr=run.toy_lr),
    hparams=lambda cfg: {}, init=_init, train_episode=_train_episode, evaluate=_evaluate,
    params=lambda carry: carry.gain)


@pytest.fixture
def toy():
    algos.register(TOY)
    yield TOY
    algos.unregister(TOY.name)


def test_a_method_registered_in_a_test_trains_through_the_command_line(toy, tmp_path, capsys):
    out = tmp_path / "toy"
    cli.main(["--algo", "toy", "--env", "point3leg", "--preset", "quick", "--seeds", "2",
              "--steps", "1600", "--toy-lr", "0,0.5", "--out", str(out),
              "--no-compile-cache"])
    assert capsys.readouterr().out.startswith("Toy (toy) on PointMaze room (point3leg), 2 seeds "
                                              "x 2 sweep points")
    with open(out / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert {"toy_lr", "toy_loss", "success_rate"} <= set(rows[0])
    last = {(r["toy_lr"], r["seed"]): float(r["success_rate"]) for r in rows[-4:]}
    assert set(last) == {("0.0", "0"), ("0.0", "1"), ("0.5", "0"), ("0.5", "1")}
    # the gain stays 0 at lr 0 (no move, no success); at 0.5 it learns to head for the goal
    assert last["0.0", "0"] == last["0.0", "1"] == 0.0
    assert min(last["0.5", "0"], last["0.5", "1"]) > 0.5
    saved = json.loads((out / "config.json").read_text())["config"]
    assert (saved["algo"], saved["toy_lr"]) == ("toy", [0.0, 0.5])
    summary = json.loads((out / "summary.json").read_text())
    assert [p["name"] for p in summary["points"]] == ["Toy toy lr=0.0", "Toy toy lr=0.5"]


def test_a_registered_methods_flags_are_in_help_and_checked(toy, capsys):
    with pytest.raises(SystemExit):
        cli.parse_cli(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "toy (toy): --toy-lr TOY_LR step size of the toy's gain" in text
    assert "one of flat, dhrl, flr_dhrl, pig, flr_pig, higl, toy" in text
    for argv, message in ((["--algo", "flat", "--toy-lr", "1"], "--toy-lr applies to toy only"),
                          (["--algo", "toy", "--toy-lr", "-1"], "--toy-lr must be >= 0"),
                          (["--algo", "toy", "--flr-alpha", "0"], "--flr-alpha applies to")):
        with pytest.raises(SystemExit):
            cli.parse_args(["--env", "point3leg", "--out", "/tmp/toy-never", *argv])
        assert message in capsys.readouterr().err


def _code(path: pathlib.Path) -> ast.Module:
    return ast.parse(path.read_text())


def test_no_method_is_named_outside_the_methods_package():
    """Outside flrjax/algos/ no string is a method's name and no code tests a name's
    prefix: every method-specific choice is the method's (its options, validate, resolved,
    base)."""
    names = set(algos.names())
    found = []
    for path in PACKAGE.rglob("*.py"):
        if "algos" in path.relative_to(PACKAGE).parts:
            continue
        for node in ast.walk(_code(path)):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and (
                    node.value in names or re.fullmatch(r"flr_", node.value)):
                found.append(f"{path.name}:{node.lineno}: {node.value!r}")
    assert not found, found


def _imports(path: pathlib.Path, module: str) -> set[str]:
    """The flrjax modules ``path`` imports (type-checking imports too)."""
    out = set()
    for node in ast.walk(_code(path)):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                out.add(sub if _module_path(sub) else node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.startswith("flrjax") and m != module and _module_path(m)}


def _module_path(module: str) -> pathlib.Path | None:
    base = PACKAGE.parent.joinpath(*module.split("."))
    for p in (base.with_suffix(".py"), base / "__init__.py"):
        if p.exists():
            return p
    return None


def test_the_package_has_no_import_circle():
    """The import graph of flrjax (each module's imports of other flrjax modules, a package's
    __init__ counted as the package) has no cycle."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        modules[".".join(parts)] = path
    graph = {m: _imports(p, m) for m, p in modules.items()}
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(m: str, stack: list[str]) -> bool:
        state[m] = 1
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                cycle.extend(stack[stack.index(n):] + [m, n] if n in stack else [m, n])
                return True
            if n not in state and visit(n, [*stack, m]):
                return True
        state[m] = 2
        return False

    assert not any(visit(m, []) for m in sorted(graph) if m not in state), cycle
