"""FLR's settings from the run's flags (value chunk and precision by device), and eq. 5's
values computed for a sweep's active runs alone."""

import jax
import numpy as np
import pytest

from flrjax import cli, config
from flrjax.agents import gc_td3
from flrjax.algos import flr as flr_module


def test_flr_value_chunk_flag_reaches_the_flr_config():
    """--flr-value-chunk: unset is FLRConfig's 128 on a CPU, 0 the whole batch (None), N
    chunks of N; --flr-precision: unset is float32 on a CPU."""
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-value-chunk"]
    for argv, want in (([], 128), (["--flr-value-chunk", "0"], None),
                       (["--flr-value-chunk", "256"], 256)):
        cfg = cli.parse_args([*base, *argv])
        assert flr_module.from_run(cfg).value_chunk == want, argv
        assert config.algo_config(cfg).flr.value_chunk == want, argv
        assert flr_module.from_run(cfg).value_dtype == "float32"
    pig = cli.parse_args([*base, "--algo", "flr_pig", "--flr-value-chunk", "0"])
    assert config.algo_config(pig).flr.value_chunk is None


def test_flr_evaluates_the_whole_batch_in_bf16_by_default_on_a_gpu(monkeypatch):
    """On a GPU: the whole batch, bf16 operands, the fused kernel (for widths Triton can
    tile, on one device or several: each runs its own runs' program); the flags win."""
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-value-chunk"]
    monkeypatch.setattr(flr_module.jax, "default_backend", lambda: "gpu")
    flr = flr_module.from_run(cli.parse_args(base))
    assert flr.value_chunk is None and flr.value_dtype == "bfloat16"
    assert flr.value_kernel == "fused"
    flr = flr_module.from_run(cli.parse_args([*base, "--flr-value-chunk", "128",
                                                    "--flr-precision", "float32"]))
    assert flr.value_chunk == 128 and flr.value_dtype == "float32"
    assert flr.value_kernel == "xla"  # the fused kernel is bf16 only: the default yields
    flr = flr_module.from_run(cli.parse_args([*base, "--hidden", "48"]))
    assert flr.value_kernel == "xla"  # and to widths Triton cannot tile
    flr = flr_module.from_run(cli.parse_args([*base, "--value-kernel", "xla"]))
    assert (flr.value_dtype, flr.value_kernel) == ("bfloat16", "xla")
    # runs split over two GPUs (padded or not): each GPU's program takes the kernel
    monkeypatch.setattr(flr_module.jax, "device_count", lambda: 2)
    for seeds in ("2", "3"):
        run = cli.parse_args([*base, "--seeds", seeds, "--value-kernel", "fused"])
        assert flr_module.from_run(run).value_kernel == "fused"
        assert flr_module.from_run(cli.parse_args([*base, "--seeds", seeds])).value_kernel \
            == "fused"
    with pytest.raises(SystemExit):
        cli.parse_args([*base, "--hidden", "48", "--value-kernel", "fused"])


@pytest.mark.parametrize("obs_norm", [False, True])
def test_active_runs_value_evaluates_the_active_runs_alone(obs_norm):
    """Under a vmap over as many runs as ``active`` has, the values of the active runs are
    gc_td3.value's and the others' are 0, and the inactive runs' products are not computed
    (fewer FLOPs); under a vmap of another size, or none, it is gc_td3.value. With
    ``obs_norm`` the agent carries brax's running statistics, whose count rebuilds itself
    as arrays."""
    td3 = gc_td3.TD3Config(hidden_sizes=(16, 16), obs_norm=obs_norm)
    agents = jax.vmap(lambda k: gc_td3.init(k, 6, 2, 3, td3))(
        jax.random.split(jax.random.key(0), 3))
    obs = jax.random.normal(jax.random.key(1), (3, 5, 6))
    goals = jax.random.normal(jax.random.key(2), (3, 5, 4, 2))
    active = (False, True, False)

    def values(agent, o, g):
        return flr_module.active_runs_value(agent, active, gc_td3.value)(o, g)

    plain = jax.vmap(lambda a, o, g: gc_td3.value(a, o, g))(agents, obs, goals)
    got = np.asarray(jax.jit(jax.vmap(values))(agents, obs, goals))
    np.testing.assert_array_equal(got[1], plain[1])
    np.testing.assert_array_equal(got[[0, 2]], 0.0)
    def flops(f) -> float:
        return jax.jit(jax.vmap(f)).lower(agents, obs, goals).cost_analysis()["flops"]

    assert flops(values) < 0.5 * flops(lambda a, o, g: gc_td3.value(a, o, g))  # one run of 3
    two = jax.tree.map(lambda x: x[:2], (agents, obs, goals))
    np.testing.assert_allclose(jax.vmap(values)(*two), plain[:2], rtol=1e-6)
    one = jax.tree.map(lambda x: x[0], (agents, obs, goals))
    np.testing.assert_allclose(values(*one), plain[0], rtol=1e-6)


def test_active_runs_value_passes_each_runs_wanted_rows_on():
    """``rows`` (eq. 5's reaching count, :func:`rewards.forward_looking_reward`'s
    ``reached_first``) reaches the value function of each active run under the vmap."""
    td3 = gc_td3.TD3Config(hidden_sizes=(16, 16))
    agents = jax.vmap(lambda k: gc_td3.init(k, 6, 2, 3, td3))(
        jax.random.split(jax.random.key(0), 3))
    obs = jax.random.normal(jax.random.key(1), (3, 5, 6))
    goals = jax.random.normal(jax.random.key(2), (3, 5, 4, 2))
    rows = jax.numpy.array([4, 2, 1])

    def front(agent, o, g, rows):  # the values of the first `rows` transitions, 0 past them
        return gc_td3.value(agent, o, g) * (jax.numpy.arange(o.shape[0]) < rows)[:, None]

    got = jax.jit(jax.vmap(lambda a, o, g, n: flr_module.active_runs_value(
        a, (True, True, False), front)(o, g, rows=n)))(agents, obs, goals, rows)
    want = jax.vmap(front)(agents, obs, goals, rows)
    np.testing.assert_allclose(got[:2], want[:2], rtol=1e-6)
    np.testing.assert_array_equal(got[2], 0.0)
    assert np.all(np.asarray(got[1, 2:]) == 0.0) and np.all(np.asarray(got[1, :2]) != 0.0)
