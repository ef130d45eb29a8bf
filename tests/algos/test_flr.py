"""The run's flags translated into FLR's settings: value chunk and precision by device."""



from flrjax import cli, config
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
    assert config.algo_config(pig).base.flr.value_chunk is None


def test_flr_evaluates_the_whole_batch_in_bf16_by_default_on_a_gpu(monkeypatch):
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-value-chunk"]
    monkeypatch.setattr(flr_module.jax, "default_backend", lambda: "gpu")
    flr = flr_module.from_run(cli.parse_args(base))
    assert flr.value_chunk is None and flr.value_dtype == "bfloat16"
    flr = flr_module.from_run(cli.parse_args([*base, "--flr-value-chunk", "128",
                                                    "--flr-precision", "float32"]))
    assert flr.value_chunk == 128 and flr.value_dtype == "float32"
