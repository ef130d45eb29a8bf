"""claims: exact permutation p, sample std, bootstrap intervals, windows and the verdict table."""

import itertools
import json
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "experiments"))
import claims  # noqa: E402


def _brute_force_p(a, b):
    """Every relabelling of the pooled values, counted one by one in plain Python."""
    pooled, na = list(a) + list(b), len(a)
    observed = abs(sum(a) / na - sum(b) / len(b))
    hits = total = 0
    for idx in itertools.combinations(range(len(pooled)), na):
        x = [pooled[i] for i in idx]
        y = [pooled[i] for i in range(len(pooled)) if i not in idx]
        hits += abs(sum(x) / len(x) - sum(y) / len(y)) >= observed - 1e-12
        total += 1
    return hits / total


@pytest.mark.parametrize("a, b", [([0.1, 0.4, 0.35], [0.2, 0.0, 0.05, 0.3]),
                                  ([1.0, 2.0, 2.0, 5.0], [2.0, 3.0, 0.5]),
                                  ([0.0, 0.1, 0.1, 0.2, 0.0], [0.0, 0.0, 0.0, 0.0, 0.3])])
def test_exact_permutation_p_matches_brute_force(a, b):
    assert claims.permutation_test(a, b) == pytest.approx(_brute_force_p(a, b), abs=1e-12)


def test_permutation_p_known_values():
    assert claims.permutation_test([0.0] * 5, [0.0] * 5) == 1.0
    assert claims.permutation_test([1, 2, 3], [3, 2, 1]) == 1.0  # same values: no difference
    high, low = [0.8, 0.9, 0.7, 1.0, 0.85], [0.0, 0.1, 0.05, 0.0, 0.2]
    assert claims.n_splits(5, 5) == 252
    # fully separated: only the observed split and its mirror are as extreme (two-sided)
    assert claims.permutation_test(high, low) == pytest.approx(2 / 252)
    assert claims.permutation_test(low, high) == pytest.approx(2 / 252)


def test_monte_carlo_permutation_is_seeded_and_close_to_exact():
    a, b = [0.3, 0.5, 0.2, 0.6, 0.4], [0.1, 0.3, 0.0, 0.2, 0.35]
    exact = claims.permutation_test(a, b)
    mc = claims.permutation_test(a, b, n=20_000, seed=1, max_exact=0)
    assert mc == claims.permutation_test(a, b, n=20_000, seed=1, max_exact=0)
    assert mc == pytest.approx(exact, abs=0.01)


def test_sample_std_uses_ddof_1():
    x = [1.0, 2.0, 3.0, 4.0]
    assert claims.sample_std(x) == pytest.approx(np.sqrt(5 / 3))  # not sqrt(5/4) (ddof 0)
    assert np.isnan(claims.sample_std([0.5]))


def test_numbers_that_round_to_zero_print_without_a_minus_sign():
    assert claims._num(-1e-5, 3) == "0.000"
    assert claims._num(-1e-5, 2, sign=True) == "+0.00"
    assert claims._num(-0.0125, 3) == "-0.013"


def test_bootstrap_interval_contains_the_mean_and_is_seeded():
    x = [0.1, 0.4, 0.35, 0.8, 0.6]
    lo, hi = claims.bootstrap_ci(x, n=2000, seed=0)
    assert lo <= np.mean(x) <= hi and lo >= min(x) and hi <= max(x)
    assert claims.bootstrap_ci(x, n=2000, seed=0) == (lo, hi)
    assert claims.bootstrap_ci(x, n=2000, seed=1) != (lo, hi)
    a, b = [0.8, 0.9, 0.7], [0.1, 0.0, 0.2]
    dlo, dhi = claims.bootstrap_diff_ci(a, b, n=2000, seed=0)
    assert dlo <= np.mean(a) - np.mean(b) <= dhi
    assert claims.bootstrap_diff_ci(a, b, n=2000, seed=0) == (dlo, dhi)


@pytest.mark.parametrize("diff, p, direction, expected", [
    (0.5, 0.008, ">", "confirmed"), (0.5, 0.2, ">", "partly"),
    (-0.5, 0.2, ">", "not confirmed"), (-0.5, 0.01, ">", "contradicted"),
    (0.0, 1.0, ">", "not confirmed"), (-3.0, 0.01, "<", "confirmed"),
    (0.1, 0.5, ">=", "confirmed"), (-0.1, 0.5, ">=", "partly"), (-0.1, 0.01, ">=", "contradicted"),
    (0.2, 0.02, "<=", "contradicted"), (-0.2, 0.02, "<=", "confirmed")])
def test_verdict_rule(diff, p, direction, expected):
    assert claims.verdict(diff, p, direction) == expected


def _rows(text):
    lines = text.strip().splitlines()
    keys = lines[0].split(",")
    return [dict(zip(keys, line.split(","), strict=True)) for line in lines[1:]]


def test_last_evals_window_cumulative_and_nan():
    rows = _rows("step,seed,m\n10,0,1\n20,0,2\n30,0,3\n40,0,4\n10,1,nan\n20,1,5\n30,1,7\n40,1,9")
    values, window = claims.last_evals(rows, "m", k=2, upto=30)
    assert values == {0: 2.5, 1: 6.0} and window == (20, 30)
    values, window = claims.last_evals(rows, "m", k=5, upto=30)
    assert values == {0: 2.0, 1: 6.0} and window == (10, 30)  # seed 1's nan is skipped
    values, _ = claims.last_evals(rows, "m", upto=40, cumulative=True)
    assert values == {0: 10.0, 1: 21.0}
    assert claims.reached(rows) == 40


def _write_run(path, points, steps, device):
    """A synthetic sweep CSV (``flr_alpha`` points, 5 seeds) and its grid.json."""
    os.makedirs(path.parent, exist_ok=True)
    lines = ["step,seed,flr_alpha,success_rate,falls"]
    for alpha, (success, last) in points.items():
        for step in steps:
            if step > last:
                continue
            for seed in range(5):
                value = success(seed) if step >= 300 else 0.0
                lines.append(f"{step},{seed},{alpha},{value},{seed % 3}")
    path.write_text("\n".join(lines) + "\n")
    grid = [{"run": path.stem, "device": device, "config": {"steps": steps[-1]}}]
    (path.parent / "grid.json").write_text(json.dumps(grid))


def test_table_builder_on_a_synthetic_csv(tmp_path):
    steps = list(range(100, 1100, 100))
    # FLR (alpha 0.01) ends at step 800, DHRL (alpha 0) at 1000: compared up to 800
    _write_run(tmp_path / "fig" / "run.csv",
               {"0.01": (lambda s: 0.5 + 0.1 * s, 800), "0": (lambda s: 0.1 * (s % 2), 1000)},
               steps, "NVIDIA H100 80GB HBM3")
    flr = claims.Arm("FLR", "fig/run.csv", (("flr_alpha", "0.01"),))
    base = claims.Arm("DHRL", "fig/run.csv", (("flr_alpha", "0"),))
    table = claims.build_table([
        claims.Claim("FLR > DHRL", "paper", "success_rate", flr, base),
        claims.Claim("FLR < DHRL", "paper", "success_rate", flr, base, "<"),
        claims.Claim("falls equal", "paper", "falls", flr, base, "<", cumulative=True),
        claims.Claim("at 1000", "paper", "success_rate", flr, base, min_step=1000),
        claims.Claim("missing", "paper", "success_rate", flr,
                     claims.Arm("HIGL", "fig/higl.csv")),
    ], root=str(tmp_path))
    first = table[0]
    assert first.common == 800 and first.windows == ((400, 800), (400, 800))
    assert first.reached == (800, 1000)
    assert first.values[0] == pytest.approx({s: 0.5 + 0.1 * s for s in range(5)})
    assert first.p == pytest.approx(2 / 252) and first.exact
    assert first.diff == pytest.approx(0.7 - 0.04)
    assert first.ci[0] <= first.diff <= first.ci[1]
    assert first.info[0].device == "NVIDIA H100 80GB HBM3" and first.info[0].planned == 1000
    assert table[0].verdict == "confirmed" and table[1].verdict == "contradicted"
    assert table[2].verdict == "not confirmed"  # same falls per seed (seed % 3): no difference
    assert table[3].verdict == "not testable at 1k: `fig/run.csv` flr_alpha=0.01 reached 800"
    assert table[4].verdict == "not testable: fig/higl.csv not committed"
    text = claims.render(table, str(tmp_path))
    assert "| 1 | FLR > DHRL | paper |" in text and "**confirmed**" in text
    assert "0.008 = 2/252 (exact)" in text and "H100" in text
    assert "`fig/run.csv` at 800" in text  # the caveat lists the run cut short


def test_constant_arms_are_not_testable(tmp_path):
    _write_run(tmp_path / "run.csv", {"0.01": (lambda s: 0.0, 500), "0": (lambda s: 0.0, 500)},
               [100, 200, 300, 400, 500], "cpu")
    result = claims.evaluate(claims.Claim(
        "zero", "paper", "success_rate", claims.Arm("a", "run.csv", (("flr_alpha", "0.01"),)),
        claims.Arm("b", "run.csv", (("flr_alpha", "0"),))), str(tmp_path))
    assert result.verdict == "not testable: both arms are 0 on every seed"
    told = claims.evaluate(claims.Claim("told", "paper", "success_rate", claims.Arm("a", "x.csv"),
                                        claims.Arm("b", "x.csv"), untestable="no such run"))
    assert told.verdict == "not testable: no such run"


def test_p_cell_keeps_small_p_readable():
    """10 against 10 seeds is tested exactly (184,756 splits) and its p keeps two digits."""
    high, low = [1.0 + i for i in range(10)], [-1.0 - i for i in range(10)]
    claim = claims.Claim("x", "paper", "success_rate", claims.Arm("a", "a.csv"),
                         claims.Arm("b", "b.csv"))
    p = claims.permutation_test(high, low)
    assert p == pytest.approx(2 / 184_756)
    res = claims.Result(claim, values=(dict(enumerate(high)), dict(enumerate(low))), p=p)
    assert claims.p_cell(res) == "1.1e-05 = 2/184,756 (exact)"
    res.p = 0.5
    assert claims.p_cell(res) == "0.500 = 92,378/184,756 (exact)"


def test_mixed_devices_caveat_names_one_claim_in_the_singular(tmp_path):
    steps = [100, 200, 300, 400, 500]
    _write_run(tmp_path / "a" / "run.csv", {"0.01": (lambda s: 0.5 + 0.1 * s, 500)}, steps,
               "NVIDIA H100 80GB HBM3")
    _write_run(tmp_path / "b" / "run.csv", {"0": (lambda s: 0.1 * s, 500)}, steps,
               "NVIDIA H200")
    flr = claims.Arm("FLR", "a/run.csv", (("flr_alpha", "0.01"),))
    base = claims.Arm("DHRL", "b/run.csv", (("flr_alpha", "0"),))
    text = claims.render(claims.build_table(
        [claims.Claim("FLR > DHRL", "paper", "success_rate", flr, base)],
        root=str(tmp_path)), str(tmp_path))
    assert "in claim 1 the two arms ran on different GPUs" in text


def test_only_the_shared_pairs_own_runs_rest_on_it():
    """The fresh-seed program's folder starts with the shared pair's name but is another run."""
    assert claims._in_shared_pair(os.path.dirname(claims.DHRL3))
    assert not claims._in_shared_pair(os.path.dirname(claims.FRESH3))
