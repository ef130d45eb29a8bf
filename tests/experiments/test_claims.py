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
    assert "in claim 1 (H100, 5 seeds, against H200, 5 seeds) the two arms ran on" in text


def test_only_the_shared_pairs_own_runs_rest_on_it():
    """The fresh-seed program's folder starts with the shared pair's name but is another run."""
    assert claims._in_shared_pair(os.path.dirname(claims.DHRL3))
    assert not claims._in_shared_pair(os.path.dirname(claims.FRESH3))


def _exact_p(a, b):
    """The permutation p in exact rational arithmetic on the decimals the float32 values stand
    for: ties are ties, with no rounding."""
    from fractions import Fraction
    a, b = [Fraction(str(v)) for v in a], [Fraction(str(v)) for v in b]
    pooled, na, nb = a + b, len(a), len(b)
    observed = abs(sum(a) / na - sum(b) / nb)
    hits = total = 0
    for idx in itertools.combinations(range(len(pooled)), na):
        s = sum(pooled[i] for i in idx)
        hits += abs(s / na - (sum(pooled) - s) / nb) >= observed
        total += 1
    return Fraction(hits, total)


@pytest.mark.parametrize("a, b, ties", [
    ([0.3, 0.8, 0.7, 0.0, 0.4], [0.9, 0.6, 0.0, 0.8, 0.8], 118),  # 112 with a 1e-9 tolerance
    ([0.9, 0.8, 0.7, 0.9, 0.6], [0.7, 0.6, 0.1, 0.3, 0.2], 10),
    ([0.62, 0.86, 0.74], [0.58, 0.22, 0.46, 0.7], 4)])
def test_float32_ties_count_as_ties(a, b, ties):
    """Success rates are stored as float32 text (0.1 -> 0.10000000149011612): splits whose
    difference ties the observed one in exact arithmetic must count, as the exact p counts
    them, although float32 rounding puts some of them below it by more than float64 noise."""
    f32 = [float(np.float32(x)) for x in a], [float(np.float32(x)) for x in b]
    exact = _exact_p(a, b)
    assert exact * claims.n_splits(len(a), len(b)) == ties
    assert claims.permutation_test(*f32) == pytest.approx(float(exact), abs=1e-12)


def test_float32_tie_example_is_below_the_old_tolerance():
    """The case the tolerance is for: 0.3 vs 0.1 + 0.2 in float32 differ by ~7e-9, more than a
    float64-noise tolerance (1e-9) and less than STORED_RTOL of the scale."""
    gap = float(np.float32(0.3)) - (float(np.float32(0.1)) + float(np.float32(0.2)))
    assert 1e-9 * 1.3 < abs(gap) < claims.tie_tolerance(np.array([0.3]))


@pytest.mark.parametrize("name, count, splits", [
    ("FLR+DHRL > DHRL, ant4leg (\"slight gains\"), 10 seeds", 58, 184_756),
    ("α = 0.01 > α = 0.002, the paper's update ratio", 16, 252),
    ("FLR+DHRL robust to 96 initial episodes (not below 192)", 134, 252),
    ("FLR+DHRL robust to 48 initial episodes (not below 192)", 6, 252)])
def test_committed_claims_count_their_ties(name, count, splits):
    """On the committed CSVs the exact p counts every tied split (claim 5: 58 of 184,756)."""
    claim = next(c for c in claims.claims() if c.name == name)
    if not os.path.exists(os.path.join(claims.ROOT, claim.a.csv)):
        pytest.skip(f"{claim.a.csv} not committed")
    res = claims.evaluate(claim)
    assert claims.n_splits(*res.n) == splits
    assert res.p * splits == pytest.approx(count, abs=1e-6)


def _brute_sign_flip(a, b):
    d = [x - y for x, y in zip(a, b, strict=True)]
    observed = abs(sum(d)) / len(d)
    hits = sum(abs(sum(s * v for s, v in zip(signs, d, strict=True))) / len(d) >= observed - 1e-12
               for signs in itertools.product((1, -1), repeat=len(d)))
    return hits / 2 ** len(d)


@pytest.mark.parametrize("a, b", [([0.3, 0.5, 0.2, 0.6, 0.4], [0.1, 0.6, 0.0, 0.2, 0.35]),
                                  ([1.0, 2.0, 3.0], [0.5, 2.5, 1.0]),
                                  ([0.2, 0.2, 0.3, 0.1], [0.2, 0.1, 0.4, 0.0])])
def test_sign_flip_test_matches_brute_force(a, b):
    assert claims.sign_flip_test(a, b) == pytest.approx(_brute_sign_flip(a, b), abs=1e-12)


def test_sign_flip_test_known_values():
    assert claims.sign_flip_test([1.0] * 5, [0.0] * 5) == pytest.approx(2 / 32)
    assert claims.sign_flip_test([0.5, 0.2], [0.5, 0.2]) == 1.0  # no difference
    assert claims.smallest_p(5, 5, paired=True) == 2 / 32
    assert claims.smallest_p(5, 5, paired=False) == 2 / 252
    assert claims.smallest_p(5, 3, paired=False) == 1 / 56


def test_holm_adjusts_step_down_and_keeps_order():
    # sorted 0.005, 0.01, 0.03, 0.04: x4 = 0.02, x3 = 0.03, x2 = 0.06, x1 = 0.04 -> max 0.06
    assert claims.holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    adjusted = claims.holm([0.2, float("nan"), 0.5, 0.9])
    assert np.isnan(adjusted[1])  # outside the family, and not counted in m = 3
    assert adjusted[0] == pytest.approx(0.6) and adjusted[2] == pytest.approx(1.0)
    assert adjusted[3] == pytest.approx(1.0)


def test_verdict_words_use_holm_and_say_what_differs(tmp_path):
    """Within a family the verdict follows Holm's p; a significant opposite sign reads
    "differs under" where the protocol differs, "partly" under a stricter reading; an
    untried setting is "beyond the paper"; two windows of the same seeds are paired."""
    steps = list(range(100, 1100, 100))
    _write_run(tmp_path / "run.csv",
               {"0.01": (lambda s: 0.5 + 0.1 * s, 1000), "0": (lambda s: 0.1 * (s % 2), 1000)},
               steps, "cpu")
    flr = claims.Arm("FLR", "run.csv", (("flr_alpha", "0.01"),))
    base = claims.Arm("DHRL", "run.csv", (("flr_alpha", "0"),))
    half = claims.Arm("FLR, half-way", "run.csv", (("flr_alpha", "0.01"),), frac=0.2)
    table = claims.build_table([
        claims.Claim("reversed", "paper", "success_rate", base, flr),
        claims.Claim("reversed, other protocol", "paper", "success_rate", base, flr,
                     differs="another ratio"),
        claims.Claim("stricter", "paper", "success_rate", base, flr, ">=", reading="stricter"),
        claims.Claim("untried", "paper", "success_rate", flr, base, beyond="never tried"),
        claims.Claim("end vs start", "paper", "success_rate", flr, half),
    ], root=str(tmp_path))
    assert [r.p for r in table[:4]] == pytest.approx([2 / 252] * 4)
    assert all(r.p_holm == pytest.approx(4 * 2 / 252) for r in table[:4])  # family of 4
    assert table[0].verdict == "contradicted"
    assert table[1].verdict == "differs under another ratio"
    assert table[2].verdict == "partly" and "stricter" in table[2].judged
    assert table[3].verdict == "beyond the paper"
    assert table[3].judged[0] == "never tried; the data alone: confirmed"
    paired = table[4]
    assert paired.claim.paired and paired.p == pytest.approx(2 / 32)
    assert np.isnan(paired.p_holm)
    assert paired.verdict.startswith("not testable at 0.05: a paired test over 5 seeds")
    assert paired.judged == ["the paper's sign on 5 of 5 seeds"]
    text = claims.render(table, str(tmp_path))
    assert "0.008 = 2/252 (exact); Holm 0.032" in text
    assert "0.062 = 2/32 (paired, exact)" in text
