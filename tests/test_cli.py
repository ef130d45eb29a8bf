"""The command line: one-line errors on bad input, presets, the compilation cache, --help,
--out checks and the main command."""

import csv
import dataclasses
import json
import os
import warnings

import jax
import numpy as np
import pytest

from flrjax import cli, config, launch_cache, metrics_io, presets, validation
from flrjax.algos.common import num_devices, padded_runs
from flrjax.options import dashed, int_value
from tests.tiny import TINY


@pytest.mark.parametrize("argv,message", [
    (["--env", "nope"], "unknown env 'nope'"),
    (["--algo", "ppo"], "unknown algo 'ppo'"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--steps", "1001"], "must be a multiple of"),
    (["--num-envs", "3", "--updates-per-step", "0.5"], "must be a positive integer"),
    (["--buffer-episodes", "2", "--num-envs", "4"], "--buffer-episodes"),
    (["--seeds", "two"], "argument --seeds: 'two' is not an integer"),
    (["--steps", "1.5e0"], "argument --steps: '1.5e0' is not an integer"),
    (["--steps", "1e-3"], "argument --steps: '1e-3' is not an integer"),
    (["--steps", "inf"], "argument --steps: 'inf' is not an integer"),
    (["--initial-episodes", "4,2.5"], "'2.5' is not an integer"),
    (["--polyak", "1.5"], "--polyak must be in [0, 1)"),
    (["--subgoal-freq", "10"], "--subgoal-freq applies to dhrl, flr_dhrl, pig, flr_pig, higl only"),
    (["--algo", "dhrl", "--subgoal-freq", "7"], "must divide the episode length"),
    (["--algo", "dhrl", "--flr-alpha", "0.01"], "applies to flr_dhrl, flr_pig only"),
    (["--algo", "flr_dhrl", "--flr-alpha", "-0.01"], "--flr-alpha must be >= 0"),
    (["--algo", "flr_dhrl", "--flr-next", "far"], "--flr-next must be one of sample, goal"),
    (["--algo", "dhrl", "--max-landmarks", "500", "--landmark-sample", "100"],
     "--max-landmarks (500) must be <="),
    (["--checkpoint-every", "-1"], "--checkpoint-every must be >= 0"),
    (["--batch-size", "5000", "--buffer-episodes", "4"], "larger than the replay buffer"),
    (["--flr-eps", "nan", "--algo", "flr_dhrl"], "must be a finite number"),
    (["--algo", "dhrl", "--flr-alpha", "0.01,0.1"], "applies to flr_dhrl, flr_pig only"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,0.01"], "a sweep needs distinct values"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,-1"], "--flr-alpha must be >= 0"),
    (["--algo", "flr_dhrl", "--flr-next", "goal", "--flr-eps", "1,2"], "means nothing"),
    (["--algo", "flr_dhrl", "--flr-alpha", "0.01,x"], "invalid number list value"),
    (["--initial-episodes", "4,-1"], "--initial-episodes must be >= 0"),
    (["--initial-episodes", "4,4"], "a sweep needs distinct values"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=0; hidden=32"], "each point is FIELD=VALUE"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=x"], "not a number"),
    (["--algo", "flr_dhrl", "--sweep", "flr-alpha=0.01; flr-eps=2"], "the points must differ"),
    (["--algo", "flr_dhrl", "--sweep", "flr-eps=1", "--flr-alpha", "0,0.01"],
     "--sweep lists every point"),
    (["--algo", "dhrl", "--sweep", "flr-alpha=0"], "applies to flr_dhrl, flr_pig only"),
    (["--algo", "flr_dhrl", "--sweep", "flr-next=far"], "--flr-next must be one of sample, goal"),
    (["--algo", "flr_dhrl", "--sweep", "initial-episodes=-1"], "must be >= 0, got -1"),
    (["--algo", "flr_dhrl", "--sweep", ";"], "--sweep needs at least one point"),
    (["--algo", "dhrl", "--low-value", "k"], "--low-value must be one of infinite, reach_ends"),
    (["--algo", "higl", "--low-value", "reach_ends"], "--low-value applies to dhrl, flr_dhrl, "
                                                      "pig, flr_pig only"),
    (["--algo", "pig", "--low-value", "k_step"], "--low-value k_step: pig takes infinite, "
                                                   "reach_ends (k_step counts the steps left "
                                                   "of a high level's subgoal period; PIG has "
                                                   "no high level)"),
    (["--train-precision", "float16"], "--train-precision must be one of float32, bfloat16"),
    (["--value-kernel", "fused"], "--value-kernel applies to dhrl, flr_dhrl, flr_pig only"),
    (["--algo", "dhrl", "--value-kernel", "triton"], "--value-kernel must be one of xla, fused"),
    (["--algo", "dhrl", "--value-kernel", "fused", "--subgoal-test-precision", "bfloat16",
      "--critic-layer-norm"], "--value-kernel fused has no LayerNorm: drop --critic-layer-norm"),
    (["--algo", "flr_dhrl", "--value-kernel", "fused", "--flr-precision", "float32"],
     "needs --flr-precision bfloat16"),
    (["--algo", "dhrl", "--value-kernel", "fused", "--subgoal-test-precision", "float32"],
     "needs --subgoal-test-precision bfloat16"),
    (["--algo", "flr_pig", "--value-kernel", "fused"], "needs --flr-precision bfloat16 (the "
                                                       "default on a GPU only)"),
    (["--algo", "dhrl", "--value-kernel", "fused", "--subgoal-test-precision", "bfloat16",
      "--hidden", "48"], "--value-kernel fused needs --hidden a power of two"),
    (["--lr-critic", "1e-3,0"], "--lr-critic must be > 0, got 0.0"),
    (["--algo", "dhrl", "--high-lr-actor=-1e-4"], "--high-lr-actor must be > 0"),
    (["--lr-critic", "-1e-3"], "--lr-critic must be > 0, got -0.001"),
    (["--target-noise", "-1e-1,0.2"], "--target-noise must be >= 0, got -0.1"),
    (["--gamma", "1"], "--gamma must be in (0, 1), got 1.0"),
    (["--sweep", "gamma=0.9; gamma=0"], "--gamma must be in (0, 1), got 0.0"),
    (["--polyak", "0.9,1"], "--polyak must be in [0, 1), got 1.0"),
    (["--noise-eps", "-0.1"], "--noise-eps must be >= 0"),
    (["--random-eps", "1.5"], "--random-eps must be in [0, 1]"),
    (["--algo", "pig", "--subgoal-noise-eps", "1"], "--subgoal-noise-eps applies to"),
    (["--target-noise", "0.1,-0.1"], "--target-noise must be >= 0"),
    (["--future-p", "1.5"], "--future-p must be in [0, 1], got 1.5"),
    (["--algo", "higl", "--future-p", "0.5"], "--future-p applies to flat, dhrl"),
    (["--high-lr-critic", "3e-4"], "--high-lr-critic applies to dhrl, flr_dhrl, higl only"),
    (["--algo", "pig", "--high-lr-actor", "1e-4,3e-4"], "--high-lr-actor applies to"),
    (["--lr-actor", "1e-4,1e-4"], "--lr-actor: a sweep needs distinct values"),
    (["--sweep", "batch-size=64"], "FIELD one of future-p"),
    (["--devices", "0"], "--devices must be in 1..1 (the visible devices), got 0"),
])
def test_bad_flags_give_one_line_errors(argv, message, capsys):
    with pytest.raises(SystemExit) as e:
        cli.parse_args(["--env", "point3leg", "--algo", "flat", *argv])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "Traceback" not in "\n".join(err)


def test_presets_and_overrides():
    cfg = cli.parse_args(["--env", "point4leg", "--preset", "quick", "--seeds", "3",
                          "--out", "/tmp/x"])
    assert cfg.seeds == 3 and cfg.hidden == presets.PRESETS["quick"]["hidden"]
    assert cfg.steps % cfg.steps_per_chunk == 0
    paper = cli.parse_args(["--env", "ant4leg", "--preset", "paper", "--out", "/tmp/y"])
    assert (paper.num_envs, paper.updates_per_iter, paper.batch_size) == (1, 1, 1024)
    assert not cfg.deterministic
    assert cli.parse_args(["--env", "point4leg", "--deterministic", "--out", "/tmp/z"]
                          ).deterministic


def _train_precisions(argv: list[str]) -> dict[str, list[str]]:
    """Each algo's TD3Configs' train_precision (one per level) under ``argv``."""
    base = ["--env", "point3leg", "--out", "/tmp/train-precision"]
    out = {}
    for algo in ("flat", "dhrl", "flr_dhrl", "flr_pig", "higl"):
        a = config.algo_config(cli.parse_args([*base, "--algo", algo, *argv]))
        levels = [a.low] if algo == "flat" else [a.low, a.high]
        out[algo] = [t.train_precision for t in levels]
    return out


def test_train_precision_reaches_every_level_and_is_saved_only_when_set(monkeypatch):
    """--train-precision: each level's TD3Config of every algo. Unset: float32 on a CPU; on a
    GPU bfloat16 for dhrl and flr_dhrl (checked on the ant), float32 for the rest. Unset is
    absent from config.json, so old runs' configs compare equal."""
    assert _train_precisions([]) == {
        "flat": ["float32"], **{a: ["float32"] * 2 for a in ("dhrl", "flr_dhrl", "flr_pig",
                                                            "higl")}}
    assert _train_precisions(["--train-precision", "bfloat16"]) == {
        "flat": ["bfloat16"], **{a: ["bfloat16"] * 2 for a in ("dhrl", "flr_dhrl", "flr_pig",
                                                              "higl")}}
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert _train_precisions([]) == {
        "flat": ["float32"], "dhrl": ["bfloat16"] * 2, "flr_dhrl": ["bfloat16"] * 2,
        "flr_pig": ["float32"] * 2, "higl": ["float32"] * 2}
    assert _train_precisions(["--train-precision", "float32"])["flr_dhrl"] == ["float32"] * 2
    base = ["--env", "point3leg", "--out", "/tmp/train-precision"]
    assert "train_precision" not in metrics_io.config_dict(cli.parse_args(base))
    assert metrics_io.config_dict(cli.parse_args([*base, "--train-precision", "float32"]))[
        "train_precision"] == "float32"


def test_compile_cache_is_on_by_default_in_the_users_cache_dir(monkeypatch):
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/x/cache")
    assert launch_cache.default_compile_cache() == "/x/cache/flrjax/jax"
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", "/y/jit")
    assert launch_cache.default_compile_cache() == "/y/jit"
    base = ["--env", "point4leg", "--out", "/tmp/cache-flag"]
    assert cli.parse_cli(base).compile_cache == "/y/jit"
    assert cli.parse_cli([*base, "--no-compile-cache"]).compile_cache is None


def test_flr_warns_when_alpha_exceeds_one_minus_gamma():
    with pytest.warns(UserWarning, match="eq. \\(4\\) no longer guarantees"):
        cli.parse_args(["--env", "point4leg", "--algo", "flr_dhrl", "--flr-alpha", "0.1",
                        "--out", "/tmp/flr-warn"])
    with pytest.warns(UserWarning, match="eq. \\(6\\)"):
        cli.parse_args(["--env", "point4leg", "--algo", "flr_dhrl", "--flr-eps", "0.5",
                        "--out", "/tmp/flr-warn"])
    base = ["--env", "point4leg", "--algo", "flr_dhrl", "--out", "/tmp/flr-warn"]
    with warnings.catch_warnings():  # alpha 0.03 <= 1 - gamma with gamma 0.95
        warnings.simplefilter("error")
        cli.parse_args([*base, "--flr-alpha", "0.03", "--gamma", "0.95"])
    with pytest.warns(UserWarning, match="eq. \\(4\\)"):  # each point's gamma: 0.995's
        cli.parse_args([*base, "--flr-alpha", "0.008", "--gamma", "0.99,0.995"])


@pytest.mark.parametrize("argv,message", [
    (["--algo", "flr_dhrl", "--flr-value-chunk", "-1"], "--flr-value-chunk must be >= 0"),
    (["--algo", "dhrl", "--flr-value-chunk", "64"], "applies to flr_dhrl, flr_pig only"),
    (["--algo", "flr_dhrl", "--flr-value-chunk", "64,128"], "'64,128' is not an integer"),
    (["--algo", "flr_dhrl", "--sweep", "flr-value-chunk=64"], "each point is FIELD=VALUE"),
])
def test_flr_value_chunk_bad_values_give_one_line_errors(argv, message, capsys):
    test_bad_flags_give_one_line_errors(argv, message, capsys)


def test_fuzzed_command_lines_never_show_a_traceback(capsys):
    """Random flag lists (valid, out-of-range and malformed values, unknown flags) either parse
    to a valid config or exit with argparse's one-line usage error (code 2)."""
    rng = np.random.default_rng(0)
    flags = [dashed(k) for k in config.all_flags()] + ["--preset", "--bogus"]
    values = ["0", "-1", "1", "3", "7", "100", "0.5", "1e9", "-0.01", "nan", "inf", "abc", "",
              "point4leg", "point3leg", "nope", "flat", "dhrl", "flr_dhrl", "quick", "goal"]
    for _ in range(300):
        argv = ["--env", "point4leg", "--out", "/tmp/fuzz-never-written"]
        for _ in range(rng.integers(1, 5)):
            argv += [str(rng.choice(flags)), str(rng.choice(values))]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cfg = cli.parse_args(argv)
        except SystemExit as e:
            assert e.code == 2, argv
            err = capsys.readouterr().err.strip().splitlines()
            assert err and "Traceback" not in "\n".join(err), argv
            assert err[-1].startswith("python -m flrjax.train: error:"), (argv, err[-1])
        else:
            validation.validate(cfg)  # what parsed is valid


def test_help_groups_every_flag_and_shows_the_defaults(capsys):
    with pytest.raises(SystemExit):
        cli.parse_cli(["--help"])
    text = " ".join(capsys.readouterr().out.split())  # unwrapped
    for flag in config.all_flags():  # each flag once, with its help (a switch with its no-)
        assert text.count(f" {dashed(flag)} {flag.upper()} ") + text.count(
            f" {dashed(flag)} ") + text.count(f" {dashed(flag)}, --no-{dashed(flag)[2:]} ") >= 1, \
            flag
    for title in ("run:", "learner", "graph and subgoals, default: the env's (dhrl, flr_dhrl, "
                  "pig, flr_pig, higl):", "FLR, eq. 5, default: the paper's (flr_dhrl, flr_pig)",
                  "PIG (pig, flr_pig):", "sweeps:", "checkpoints:"):
        assert title in text, title
    assert "(default flr_dhrl)" in text and "(default point3leg)" in text
    assert "(default 1)" in text
    assert "[quick 9600, paper 1200000, fast 1920000, wide 1920000, tuned 1920000]" in text
    assert ("--devices DEVICES devices the runs (seeds x sweep points) are split over, padded "
            "with spare runs to a multiple of it (default: every visible device, at most one "
            "per run") in text
    assert ("several hosts (jax.distributed; --out on a file system every process sees): "
            "--distributed one run over several processes") in text
    for flag in ("--lr-actor", "--lr-critic", "--high-lr-actor", "--high-lr-critic",
                 "--polyak", "--gamma", "--noise-eps", "--random-eps", "--target-noise",
                 "--future-p", "--subgoal-noise-eps"):
        assert flag in text and flag[2:].replace("-", "_") in config.sweep_fields(), flag
    assert "a comma list trains them as sweep points in one program" in text
    for flag in ("batch-size", "hidden", "buffer-episodes", "num-envs"):
        assert f"--{flag} " in text and flag.replace("-", "_") not in config.sweep_fields()
    assert text.count("shapes the program: one value") == 4


def test_the_main_command_trains_flr_dhrl_with_the_tuned_preset_on_a_gpu(monkeypatch):
    cpu = cli.parse_cli(["--env", "ant3leg", "--seeds", "5", "--out", "/tmp/never-made"])
    assert (cpu.cfg.algo, cpu.preset) == ("flr_dhrl", "quick")
    assert "1 update per env step (float32 matrix operands)" in cli.start_line(cpu)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    gpu = cli.parse_cli(["--env", "ant3leg", "--seeds", "5", "--out", "/tmp/never-made"])
    assert gpu.preset == "tuned" and gpu.cfg == config.TrainConfig(
        env="ant3leg", seeds=5, out="/tmp/never-made", **presets.PRESETS["tuned"])
    assert "FLR+DHRL (flr_dhrl) on AntMaze3Leg (ant3leg), 5 seeds, preset tuned: 1,920,000 " \
           "env steps per seed in 25 chunks of 76,800, 128 envs per seed" in cli.start_line(gpu)
    assert "0.25 updates per env step (bfloat16 matrix operands)" in cli.start_line(gpu)


def test_a_boolean_flag_a_preset_sets_is_turned_off_by_its_no_form(monkeypatch):
    """``--no-obs-norm`` undoes the ``tuned`` preset's input normalisation, and only that."""
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    base = ["--env", "ant3leg", "--out", "/tmp/never-made"]
    off = cli.parse_cli([*base, "--no-obs-norm"])
    assert off.preset == "tuned" and off.cfg == config.TrainConfig(
        env="ant3leg", out="/tmp/never-made", **{**presets.PRESETS["tuned"], "obs_norm": False})
    assert cli.parse_cli([*base, "--preset", "wide", "--obs-norm"]).cfg.obs_norm


def test_on_a_host_of_gpus_a_run_takes_every_gpu_with_the_fused_kernel(monkeypatch):
    """On four GPUs the main command's 5 runs are split over all four (padded to 8), each
    device calling the fused kernel on its own runs; ``--devices 1`` keeps it on one GPU,
    and ``--value-kernel xla`` chooses XLA's kernels."""
    monkeypatch.setattr(jax, "device_count", lambda: 4)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")

    def kernels(cfg):
        algo = config.algo_config(cfg)
        return algo.flr.value_kernel, algo.subgoal_test_kernel

    def devices(*flags):
        cfg = cli.parse_cli(["--env", "ant3leg", "--seeds", "5", *flags]).cfg
        return num_devices(cfg), padded_runs(cfg), kernels(cfg)

    assert devices() == (4, 8, ("fused", "fused"))
    assert devices("--devices", "1") == (1, 5, ("fused", "fused"))
    assert devices("--devices", "2", "--value-kernel", "xla") == (2, 6, ("xla", "xla"))
    assert devices("--seeds", "1")[:2] == (1, 1)  # never a device of padding alone


def _bad_outs(tmp_path) -> dict[str, str]:
    """--out paths no run may write into, by the error they give."""
    (tmp_path / "a_file").write_text("mine")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "metrics.csv").write_text("someone's numbers")
    return {str(tmp_path / "a_file"): "is a file, not a directory",
            str(tmp_path / "a_file" / "run"): "a_file is a file, not a directory",
            str(tmp_path / "foreign"): "holds metrics.csv but no config.json"}


def test_out_paths_that_cannot_take_a_run_give_one_line_errors_and_stay_untouched(
        tmp_path, capsys):
    for out, message in _bad_outs(tmp_path).items():
        with pytest.raises(SystemExit) as e:
            cli.parse_cli(["--algo", "flat", "--out", out])
        assert e.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (out, err)
    assert (tmp_path / "a_file").read_text() == "mine"
    assert (tmp_path / "foreign" / "metrics.csv").read_text() == "someone's numbers"
    assert sorted(os.listdir(tmp_path / "foreign")) == ["metrics.csv"]


def test_fuzzed_command_lines_through_main_never_show_a_traceback(tmp_path, monkeypatch,
                                                                   capsys):
    """The whole CLI path up to training (parse, --out and --resume checks, compile cache,
    start line), with training replaced by a stub: every command line either reaches
    training with a valid config or exits with one line, code 2, and no file is changed."""
    reached = []
    monkeypatch.setattr(cli, "train", lambda cfg, **kw: reached.append(cfg) or [])
    monkeypatch.setattr(cli, "enable_compile_cache", lambda path: None)
    bad = _bad_outs(tmp_path)
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "config.json").write_text("{not json")
    run = tmp_path / "saved"
    metrics_io.prepare_out(dataclasses.replace(TINY, out=str(run)), ("step", "seed"))  # no ckpt
    outs = [*bad, str(tmp_path / "fresh"), str(run)]
    resumes = [str(tmp_path / "nowhere"), str(tmp_path / "broken"), str(run), *bad]
    rng = np.random.default_rng(1)
    flags = [dashed(k) for k in config.all_flags() if k not in ("out", "sweep")] + [
        "--preset"]
    values = ["0", "-1", "1", "2", "100", "0.5", "nan", "abc", "point3leg", "nope", "flat",
              "quick", "fast"]
    before = {p: sorted(os.listdir(p)) for p in tmp_path.iterdir() if p.is_dir()}
    for i in range(150):
        argv = ["--env", "point3leg", "--algo", "flat"]
        if i % 3 == 2:
            argv = ["--resume", str(rng.choice(resumes))]
        else:
            argv += ["--out", str(rng.choice(outs))]
        for _ in range(rng.integers(0, 3)):
            argv += [str(rng.choice(flags)), str(rng.choice(values))]
        n = len(reached)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                cli.main(argv)
        except SystemExit as e:
            assert e.code == 2 and len(reached) == n, argv
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("python -m flrjax.train: error:"), \
                (argv, err)
        else:
            assert len(reached) == n + 1, argv
            validation.validate(reached[-1])
            capsys.readouterr()
    assert reached  # some lines were valid
    assert {p: sorted(os.listdir(p)) for p in tmp_path.iterdir() if p.is_dir()} == before
    assert (tmp_path / "a_file").read_text() == "mine"


def test_a_cli_run_ends_with_a_summary_curves_and_tensorboard_events(tmp_path, capsys):
    out = str(tmp_path / "run")
    os.makedirs(out)
    (tmp_path / "run" / "notes.txt").write_text("the user's, not the run's")
    cli.main(["--env", "point3leg", "--algo", "flat", "--seeds", "2", "--steps", "8e2",
              "--episodes-per-chunk", "1", "--initial-episodes", "4", "--eval-episodes", "2",
              "--out", out, "--tensorboard", "--no-compile-cache"])
    text = capsys.readouterr().out
    assert text.startswith("flat TD3+HER (flat) on PointMaze room (point3leg), 2 seeds, "
                           "preset quick")
    assert "done: 800 of 800 env steps per seed, 2 seeds" in text
    assert "± is the sample std" in text
    files = sorted(os.listdir(out))
    assert {"config.json", "metrics.csv", "summary.json", "curves.png", "checkpoints"} <= \
        set(files) and any(f.startswith("events.out.tfevents") for f in files)
    for f in ("summary.json", "curves.png", "metrics.csv"):
        assert os.path.join(out, f) in text
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    with open(os.path.join(out, "metrics.csv")) as f:
        last = [float(r["success_rate"]) for r in csv.DictReader(f) if r["step"] == "800"]
    assert summary["points"][0]["success"]["mean"] == pytest.approx(np.mean(last))
    assert summary["env_steps_per_seed"] == 800 and summary["seeds"] == 2
    with open(os.path.join(out, "config.json")) as f:
        config = json.load(f)
    assert set(config["git"]) == {"commit", "clean"} and config["command"]
    assert sorted(summary["files"]) == sorted(f for f in files if f != "notes.txt")


@pytest.mark.parametrize("text,value", [("1920000", 1_920_000), ("1.92e6", 1_920_000),
                                        ("1e9", 10**9), ("1E3", 1000), (" 48000 ", 48_000),
                                        ("-1", -1), ("0", 0), ("1_000", 1000)])
def test_integers_are_taken_in_any_notation_that_names_one(text, value):
    assert int_value(text) == value and isinstance(int_value(text), int)


def test_steps_in_scientific_notation_parse_to_the_integer():
    cfg = cli.parse_args(["--env", "ant3leg", "--steps", "1.92e6", "--num-envs", "16",
                          "--out", "/tmp/never-made"])
    assert cfg.steps == 1_920_000 and isinstance(cfg.steps, int)
    assert cli.parse_args(["--env", "point3leg", "--algo", "flat", "--seeds", "2e0",
                           "--out", "/tmp/never-made"]).seeds == 2
    swept = cli.parse_args(["--env", "point3leg", "--algo", "flr_dhrl", "--sweep",
                            "initial-episodes=4.8e1; initial-episodes=96",
                            "--out", "/tmp/never-made"])
    assert config.sweep_points(swept) == [{"initial_episodes": 48}, {"initial_episodes": 96}]


def test_the_start_line_reads_right_for_one_of_everything():
    one = cli.parse_cli(["--env", "point3leg", "--algo", "flat", "--num-envs", "1",
                         "--steps", "100", "--episodes-per-chunk", "1", "--buffer-episodes", "4",
                         "--batch-size", "32", "--out", "/tmp/never-made"])
    line = cli.start_line(one)
    assert "1 seed, preset quick: 100 env steps per seed in 1 chunk of 100, 1 env per seed, " \
           "1 update per env step" in line
    assert "(s)" not in line and "initial random episodes" not in line


def test_the_start_line_says_how_initial_episodes_round_up_to_whole_rounds():
    """``--initial-episodes`` counts per seed over all its envs in whole rounds of them."""
    cfg = cli.parse_cli(["--env", "point3leg", "--num-envs", "128", "--steps", "51200",
                         "--initial-episodes", "192,256,300", "--out", "/tmp/never-made"])
    assert "operands), initial random episodes run 192 as 256, 300 as 384 (whole rounds of " \
           "128 envs); " in cli.start_line(cfg)


def test_warnings_print_as_one_line(tmp_path):
    """``--flr-alpha 2`` warns (eq. 4) in one line naming the command, not Python's two lines
    with a file, line number and source line; the error that follows is one line too."""
    import subprocess
    import sys

    (tmp_path / "a_file").write_text("")
    res = subprocess.run([sys.executable, "-m", "flrjax.train", "--env", "point3leg",
                          "--algo", "flr_dhrl", "--flr-alpha", "2", "--out",
                          str(tmp_path / "a_file")], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.splitlines() == [
        "python -m flrjax.train: warning: alpha=2.0 > 1 - gamma=0.01: eq. (4) no longer "
        "guarantees reward >= -1, so the FLR can discourage reaching subgoals",
        f"python -m flrjax.train: error: --out {tmp_path / 'a_file'} is a file, not a "
        "directory (see --help)"]
    assert cli._format_warning(DeprecationWarning("old\n  api"), DeprecationWarning, "f.py",
                               1) == "python -m flrjax.train: DeprecationWarning: old api\n"


def test_resume_with_another_out_is_a_one_line_error(tmp_path, capsys):
    """A resumed run continues in its own directory; an --out elsewhere is refused, not
    silently dropped."""
    run = str(tmp_path / "saved")
    metrics_io.prepare_out(dataclasses.replace(TINY, out=run), ("step", "seed"))
    assert cli.parse_cli(["--resume", run, "--out", run + "/"]).cfg.out == run
    with pytest.raises(SystemExit):
        cli.parse_cli(["--resume", run, "--out", str(tmp_path / "elsewhere")])
    err = capsys.readouterr().err
    assert f"drop --out {tmp_path / 'elsewhere'}" in err and len(err.strip().splitlines()) == 1
    assert not os.path.exists(tmp_path / "elsewhere")
