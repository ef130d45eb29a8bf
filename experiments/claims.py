"""The paper's testable claims, each checked against the committed result CSVs.

    python experiments/claims.py --out docs/claims.md

Every claim compares two *arms* (a method or sweep point of one CSV, over a window of its
evaluations) on one metric. Each seed gives one number: the mean of its last ``k`` (5)
evaluations up to the window's end, or for cumulative metrics (falls) the sum of all its
evaluations up to it. The window ends at the *common step*, the last step that every arm
reached, so that arms are compared over the same steps (an arm may instead fix its own end,
to compare two windows of one run). Per arm we report the mean ± the sample standard deviation
(ddof = 1) over seeds, and for the difference of means (first arm − second) a percentile
bootstrap 95% interval (seeds resampled within each arm) and a two-sided permutation p-value
(exact over all splits of the pooled seeds when there are at most 200,000 of them: 10 against
10 seeds has 184,756).

Two windows of the *same* seeds (e.g. end vs half-way) are paired: the p-value is the exact
sign-flip test of the per-seed differences (2**n flips) and the interval resamples seeds.
*Ties*: the CSVs store float32 values, so two statistics within 1e-6 of the values' scale
count as equal (``STORED_RTOL``); a split that ties the observed difference counts as at
least as extreme.

*Raw p* is each claim's own test; *Holm p* is Holm's step-down adjustment over the family of
every claim whose exact test can reach p < 0.05 (so the family-wise error is at most 0.05), and
the verdict uses it. A claim whose test cannot reach p < 0.05 at all (a paired test over 5
seeds: smallest p 2/32; 3 against 3 seeds: 2/20) is *not testable at 0.05*, outside the family.

Verdict rule on the Holm p, for a claim that the first arm is higher (``>``) or lower (``<``):

- *confirmed*: the difference has the paper's sign and p < 0.05;
- *partly*: the paper's sign, p >= 0.05;
- *not confirmed*: the opposite sign (or no difference), p >= 0.05;
- *contradicted*: the opposite sign, p < 0.05, where our protocol and definitions match the
  paper's; where they do not, *differs under <what differs>*. No run here matches in full:
  the paper states no update ratio (we use 0.25 or DHRL's 1 per env step) and defines the
  low-level value V^l as a k-step sum, where our critic is DHRL's infinite-horizon one.

For a claim that the first arm is *not* lower (``>=``, "robust", "comparable") or not higher
(``<=``): *confirmed* when the difference has the allowed sign, *partly* when it has the other
sign with p >= 0.05 (5 seeds cannot show equivalence), *contradicted* (or *differs*) when the
other sign has p < 0.05; where "not below" is stricter than the paper's words, *partly*.
*Beyond the paper*: the paper made no such claim (an α it never tried); the note gives what
the data say. *Not testable* when a CSV is missing or both arms are the same constant (e.g.
all 0). With 5 against 5 seeds there are C(10, 5) = 252 splits, so the smallest two-sided raw
p is 2/252 ≈ 0.008 (fully separated arms).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import os
from collections.abc import Sequence

import numpy as np

from flrjax.analysis import Row, number, read_rows, run_record, same, sample_std, select

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
#: The figures' budget of env steps per seed (``experiments/figures.py``).
FIGURE_STEPS = 1_920_000
ALPHA = 0.05
#: Exact enumeration of the splits up to this many; above it, Monte Carlo permutations.
MAX_EXACT = 200_000
#: Monte Carlo permutations above MAX_EXACT.
PERMUTATIONS = 100_000
DIGITS = {"success_rate": 2, "no_plan_success_rate": 2, "reward_gap": 3, "falls": 0}



# ---------------------------------------------------------------- statistics (pure functions)

def bootstrap_ci(values: Sequence[float], n: int = 10_000, seed: int = 0,
                 level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean: ``n`` resamples with replacement, seeded so
    that the table is reproducible."""
    x = np.asarray(values, dtype=float)
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n, x.size))].mean(axis=1)
    lo, hi = np.percentile(means, [50 * (1 - level), 50 * (1 + level)])
    return float(lo), float(hi)


def bootstrap_diff_ci(a: Sequence[float], b: Sequence[float], n: int = 10_000, seed: int = 0,
                      level: float = 0.95) -> tuple[float, float]:
    """Percentile bootstrap interval of mean(a) − mean(b), each arm resampled on its own
    (the seeds of two arms are independent runs)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    rng = np.random.default_rng(seed)
    mx = x[rng.integers(0, x.size, size=(n, x.size))].mean(axis=1)
    my = y[rng.integers(0, y.size, size=(n, y.size))].mean(axis=1)
    lo, hi = np.percentile(mx - my, [50 * (1 - level), 50 * (1 + level)])
    return float(lo), float(hi)


def n_splits(na: int, nb: int) -> int:
    """How many ways the pooled values split into arms of ``na`` and ``nb``."""
    return math.comb(na + nb, na)


#: Relative tolerance of a tie, from the stored precision: the CSVs hold float32 values (unit
#: roundoff 2**-24, about 6e-8 of the value), so a mean of stored values is off by at most that
#: times the largest |value|, a difference of two means by twice that, and two differences
#: that are equal in exact arithmetic (e.g. success rates on the grid of 1/10 per evaluation,
#: 1/50 for a last-5 mean) can come out 4 * 2**-24 (about 2.4e-7) of the scale apart. 1e-6 of
#: the scale covers that with room, and any two statistics closer than that are not told apart
#: by values stored to float32's 7 significant digits.
STORED_RTOL = 1e-6


def tie_tolerance(values: np.ndarray) -> float:
    """How far apart two statistics of ``values`` may be and still count as a tie:
    :data:`STORED_RTOL` of the values' scale (their largest magnitude)."""
    return STORED_RTOL * float(np.abs(values).max(initial=0.0))


def permutation_test(a: Sequence[float], b: Sequence[float], n: int = PERMUTATIONS, seed: int = 0,
                     max_exact: int = MAX_EXACT) -> float:
    """Two-sided p-value of the difference of means under exchangeable arms: the fraction of
    splits of the pooled values whose |mean difference| is at least the observed one, ties
    (within :func:`tie_tolerance`) counted as at least.

    Exact (every split, the observed one included) when there are at most ``max_exact``
    splits; otherwise ``n`` random permutations, p = (1 + hits) / (1 + n).
    """
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    pooled = np.concatenate([x, y])
    na, nb = x.size, y.size
    total = pooled.sum()
    bar = abs(x.mean() - y.mean()) - tie_tolerance(pooled)
    if n_splits(na, nb) <= max_exact:
        idx = np.array(list(itertools.combinations(range(na + nb), na)), dtype=np.intp)
        sums = pooled[idx].sum(axis=1)
        diffs = sums / na - (total - sums) / nb
        return float(np.mean(np.abs(diffs) >= bar))
    rng = np.random.default_rng(seed)
    hits, done = 0, 0
    while done < n:
        m = min(10_000, n - done)
        perm = rng.permuted(np.broadcast_to(pooled, (m, na + nb)), axis=1)
        sums = perm[:, :na].sum(axis=1)
        hits += int(np.sum(np.abs(sums / na - (total - sums) / nb) >= bar))
        done += m
    return (1 + hits) / (1 + n)


def sign_flip_test(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided paired p-value for two windows of the same seeds (``a[i]`` and ``b[i]`` one
    seed): under no effect each seed's difference is as likely negated, so p is the fraction
    of the 2**n sign flips whose |mean difference| is at least the observed one (exact; ties
    within :func:`tie_tolerance` of the two windows' values count as at least)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = x - y
    signs = np.array(list(itertools.product((1.0, -1.0), repeat=d.size)))
    bar = abs(d.mean()) - 2 * tie_tolerance(np.concatenate([x, y]))
    return float(np.mean(np.abs(signs @ d / d.size) >= bar))


def smallest_p(na: int, nb: int, paired: bool) -> float:
    """The smallest two-sided p the exact test can give: 2 of the 2**n sign flips (paired), or
    the observed split and, for equal arms, its mirror."""
    if paired:
        return 2 / 2**na
    return (2 if na == nb else 1) / n_splits(na, nb)


def holm(p: Sequence[float]) -> list[float]:
    """Holm–Bonferroni step-down adjusted p-values over the family of the non-nan ``p`` (nan
    stays nan): the i-th smallest of m becomes max over j <= i of min(1, (m − j + 1) p_(j)),
    so adjusted p keep the raw order and rejecting adjusted p < α holds the family-wise error
    at α under any dependence between the tests."""
    raw = np.asarray(p, dtype=float)
    out = np.full(raw.shape, np.nan)
    idx = np.flatnonzero(~np.isnan(raw))
    order = idx[np.argsort(raw[idx], kind="stable")]
    m = order.size
    out[order] = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * raw[order]))
    return out.tolist()


def verdict(diff: float, p: float, direction: str, alpha: float = ALPHA) -> str:
    """The module docstring's rule; ``diff`` is first arm − second, ``direction`` the paper's
    ``>``, ``<``, ``>=`` or ``<=``."""
    sign = {">": 1, ">=": 1, "<": -1, "<=": -1}[direction]
    agrees = diff * sign > 0
    if direction in (">=", "<="):
        if agrees or diff == 0:
            return "confirmed"
        return "contradicted" if p < alpha else "partly"
    if agrees:
        return "confirmed" if p < alpha else "partly"
    return "contradicted" if diff != 0 and p < alpha else "not confirmed"


def judge(res: Result, p_holm: float, alpha: float = ALPHA) -> None:
    """Set ``res``'s verdict from its Holm-adjusted p (nan: outside the family) by the module
    docstring's rule and words, with notes on what the raw p, the paper and our protocol add."""
    c, res.p_holm = res.claim, p_holm
    na, nb = res.n
    paper_sign = {">": 1, ">=": 1, "<": -1, "<=": -1}[c.direction]
    agrees = res.diff * paper_sign > 0
    if c.paired:
        d = np.subtract(*(list(v.values()) for v in res.values))
        side = f"the paper's sign on {int(np.sum(d * paper_sign > 0))} of {na} seeds"
    else:
        side = "the paper's sign" if agrees else "the opposite sign"

    def word(p: float) -> str:
        w = verdict(res.diff, p, c.direction, alpha)
        if w == "contradicted" and c.reading:
            return "partly"
        return f"differs under {c.differs}" if w == "contradicted" and c.differs else w

    if math.isnan(p_holm):
        low = smallest_p(na, nb, c.paired)
        test = f"a paired test over {na} seeds" if c.paired else f"{na} against {nb} seeds"
        words = f"not testable at {alpha:g}: {test} cannot give p < {alpha:g} (smallest {low:.3g})"
        notes = [side]
    else:
        words, raw = word(p_holm), word(res.p)
        raw = "differs under our protocol" if raw.startswith("differs") else raw
        notes = [] if raw == words else [f"{raw} at the raw p, before Holm's correction"]
    opposite = not agrees and res.diff != 0
    if opposite and c.reading:
        notes.append(c.reading)
    if opposite and c.differs and not c.beyond and not words.startswith("differs"):
        notes.append(f"our protocol differs: {c.differs}")
    res.verdict = "beyond the paper" if c.beyond else words
    if c.beyond:
        notes.insert(0, f"{c.beyond}; the data alone: {words}")
    res.judged = notes


# ---------------------------------------------------------------- rows and windows

def reached(rows: Sequence[Row]) -> int:
    """The last step that every seed of these rows reached."""
    last: dict[str, int] = {}
    for r in rows:
        last[r["seed"]] = max(last.get(r["seed"], 0), int(r["step"]))
    return min(last.values()) if last else 0


def last_evals(rows: Sequence[Row], metric: str, k: int = 5, upto: int | None = None,
               cumulative: bool = False) -> tuple[dict[int, float], tuple[int, int]]:
    """Per seed, the mean of its last ``k`` evaluations at steps <= ``upto`` (all steps if
    None), or with ``cumulative`` the sum of all of them (Fig. 4a's cumulative falls).
    Evaluations without a value (nan) are skipped.

    Returns ``{seed: value}`` and the window ``(first step, last step)`` over all seeds: the
    caller passes one ``upto`` to every arm so that they cover the same steps.
    """
    by_seed: dict[int, list[tuple[int, float]]] = {}
    for r in rows:
        step, value = int(r["step"]), number(r.get(metric))
        if (upto is None or step <= upto) and not math.isnan(value):
            by_seed.setdefault(int(r["seed"]), []).append((step, value))
    out: dict[int, float] = {}
    first, last = math.inf, 0
    for seed, evals in sorted(by_seed.items()):
        evals.sort()
        used = evals if cumulative else evals[-k:]
        out[seed] = float(np.sum([v for _, v in used]) if cumulative
                          else np.mean([v for _, v in used]))
        first, last = min(first, used[0][0]), max(last, used[-1][0])
    return out, (int(first) if out else 0, last)


def seed_mean_curve(rows: Sequence[Row], metric: str,
                    upto: int | None = None) -> list[tuple[int, float]]:
    """The metric's mean over seeds at each evaluation step (the curve a figure plots)."""
    at: dict[int, list[float]] = {}
    for r in rows:
        step, value = int(r["step"]), number(r.get(metric))
        if (upto is None or step <= upto) and not math.isnan(value):
            at.setdefault(step, []).append(value)
    return [(s, float(np.mean(v))) for s, v in sorted(at.items())]


# ---------------------------------------------------------------- runs: device, budget, origin

@dataclasses.dataclass(frozen=True)
class RunInfo:
    """Where one arm's rows come from: the device, the planned steps and, for a CSV adopted
    from another run (``figures.py --adopt``), that run's directory."""

    device: str = "device not recorded"
    planned: int | None = None
    origin: str | None = None


def run_info(root: str, csv_rel: str, where: Sequence[tuple[str, str]] = ()) -> RunInfo:
    """The device and budget of the CSV's run (:func:`flrjax.analysis.run_record`: its
    ``config.json`` or its ``grid.json`` entry; adopted points by their sweep value)."""
    record = run_record(os.path.join(root, csv_rel))
    planned = record.get("config", {}).get("steps")
    for a in record.get("adopted", []):
        if all(same(str(a.get("point", {}).get(c, "")), v) for c, v in where):
            origin = os.path.relpath(a["dir"], "experiments/results")
            return RunInfo(a.get("device", record.get("device", RunInfo.device)), planned,
                           origin)
    return RunInfo(record.get("device", RunInfo.device), planned) if record else RunInfo()


# ---------------------------------------------------------------- claims

@dataclasses.dataclass(frozen=True)
class Arm:
    """One side of a comparison: rows of ``csv`` (relative to the results root) matching
    ``where``; its window ends at ``upto`` if given, else at ``frac`` of the common step."""

    label: str
    csv: str
    where: tuple[tuple[str, str], ...] = ()
    upto: int | None = None
    frac: float = 1.0
    metric: str | None = None  # this arm's column, if not the claim's


@dataclasses.dataclass(frozen=True)
class Claim:
    """A statement of the paper and the comparison that tests it: ``a`` (direction) ``b``."""

    name: str
    statement: str
    metric: str
    a: Arm
    b: Arm
    direction: str = ">"
    cumulative: bool = False
    k: int = 5
    trend: bool = False  # report the seed-mean curve's peak and end (reward gap)
    min_step: int = 0  # not testable unless every arm reached this step
    untestable: str | None = None
    #: How our protocol or definitions differ from the paper's (None: they match): a
    #: significant opposite sign then reads "differs under <this>", not "contradicted".
    differs: str | None = None
    #: Why the paper made no such claim (e.g. an α it never tried): the verdict is "beyond the
    #: paper" whatever the data say, and the data's own verdict goes in a note.
    beyond: str | None = None
    #: Where our test is stricter than the paper's words (e.g. "robust" tested as "not
    #: below"): a significant opposite sign then reads "partly", with this note.
    reading: str | None = None

    @property
    def paired(self) -> bool:
        """Two windows of the same rows: the same seeds on both sides, so a paired test."""
        return self.a.csv == self.b.csv and self.a.where == self.b.where


@dataclasses.dataclass
class Result:
    """One row of the table."""

    claim: Claim
    values: tuple[dict[int, float], dict[int, float]] = ({}, {})
    windows: tuple[tuple[int, int], tuple[int, int]] = ((0, 0), (0, 0))
    common: int = 0
    reached: tuple[int, int] = (0, 0)
    info: tuple[RunInfo, RunInfo] = (RunInfo(), RunInfo())
    diff: float = float("nan")
    ci: tuple[float, float] = (float("nan"), float("nan"))
    p: float = float("nan")
    exact: bool = True
    #: Holm's adjusted p over the family (nan: outside it, not tested at the 0.05 level).
    p_holm: float = float("nan")
    verdict: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)  # from the data
    judged: list[str] = dataclasses.field(default_factory=list)  # from the verdict's rule

    @property
    def n(self) -> tuple[int, int]:
        return len(self.values[0]), len(self.values[1])

    @property
    def in_family(self) -> bool:
        """Tested: a p exists and the exact test could reach p < 0.05 with these seeds."""
        return (not math.isnan(self.p) and not self.verdict.startswith("not testable")
                and smallest_p(*self.n, self.claim.paired) < ALPHA)


def evaluate(claim: Claim, root: str = ROOT) -> Result:
    """Compute one claim: per-seed values of both arms over the common window, the difference
    of means, its bootstrap interval, the permutation p and the verdict."""
    res = Result(claim)
    if claim.untestable:
        res.verdict = f"not testable: {claim.untestable}"
        return res
    arms = (claim.a, claim.b)
    missing = [a.csv for a in arms if not os.path.exists(os.path.join(root, a.csv))]
    if missing:
        res.verdict = "not testable: " + ", ".join(missing) + " not committed"
        return res
    rows = [select(read_rows(os.path.join(root, a.csv)), a.where) for a in arms]
    got = [reached(r) for r in rows]
    res.reached = (got[0], got[1])
    short = [f"`{a.csv}`{_where(a.where)} reached {_m(g)}"
             for a, g in zip(arms, got, strict=True) if g < claim.min_step]
    if short:
        res.verdict = f"not testable at {_m(claim.min_step)}: " + "; ".join(short)
        return res
    free = [g for g, a in zip(got, arms, strict=True) if not a.upto]
    res.common = min(free) if free else min(min(g, a.upto or g) for g, a in zip(got, arms,
                                                                             strict=True))
    ends = [min(a.upto, g) if a.upto else int(res.common * a.frac)
            for g, a in zip(got, arms, strict=True)]
    metrics = [a.metric or claim.metric for a in arms]
    va, wa = last_evals(rows[0], metrics[0], claim.k, ends[0], claim.cumulative)
    vb, wb = last_evals(rows[1], metrics[1], claim.k, ends[1], claim.cumulative)
    res.values, res.windows = (va, vb), (wa, wb)
    res.info = (run_info(root, claim.a.csv, claim.a.where), run_info(root, claim.b.csv,
                                                                      claim.b.where))
    if claim.paired:  # the same seeds in both windows, in the same order
        seeds = sorted(va.keys() & vb.keys())
        va, vb = {s: va[s] for s in seeds}, {s: vb[s] for s in seeds}
        res.values = (va, vb)
    a, b = list(va.values()), list(vb.values())
    if not a or not b:
        res.verdict = f"not testable: no `{claim.metric}` values in the window"
        return res
    res.diff = float(np.mean(a) - np.mean(b))
    if claim.paired:
        res.ci = bootstrap_ci(np.subtract(a, b))
        res.p = sign_flip_test(a, b)
    else:
        res.ci = bootstrap_diff_ci(a, b)
        res.p = permutation_test(a, b)
        res.exact = n_splits(len(a), len(b)) <= MAX_EXACT
    if len(set(a) | set(b)) == 1:
        res.verdict = f"not testable: both arms are {a[0]:g} on every seed"
        return res
    judge(res, res.p if res.in_family else float("nan"))
    if claim.metric.endswith("success_rate") and max(np.mean(a), np.mean(b)) <= 0.1:
        res.notes.append("both arms at or below 0.1 success: little power")
    if claim.trend:
        curve = seed_mean_curve(rows[0], metrics[0], ends[0])
        peak = max(curve, key=lambda sv: sv[1])
        if peak[0] < curve[-1][0]:
            res.notes.append(f"not monotone: the seed-mean {claim.metric} peaks at "
                             f"{peak[1]:.3f} at {_m(peak[0])} and is {_num(curve[-1][1], 3)} at "
                             f"{_m(curve[-1][0])}")
    return res


#: The first DHRL / FLR+DHRL pair (5 seeds each), the control of several figures' claims.
SHARED_PAIR = "ant3leg_dhrl_vs_flr_dhrl"


def _in_shared_pair(run: str) -> bool:
    """Whether ``run`` (a folder under results/) is one of :data:`SHARED_PAIR`'s runs (not a
    folder that merely starts with its name, as ``..._fresh_seeds`` does)."""
    return run.startswith(SHARED_PAIR + "/")


DHRL3, FLR_DHRL3 = f"{SHARED_PAIR}/dhrl/metrics.csv", f"{SHARED_PAIR}/flr_dhrl/metrics.csv"
PIG3, FLR_PIG3 = "ant3leg_pig_vs_flr_pig/pig/metrics.csv", \
    "ant3leg_pig_vs_flr_pig/flr_pig/metrics.csv"
A0, A01 = (("flr_alpha", "0"),), (("flr_alpha", "0.01"),)
#: DHRL and FLR+DHRL in one program, fresh seeds (1000-1004), bf16 eq. 5 and subgoal testing.
FRESH3 = "ant3leg_dhrl_vs_flr_dhrl_fresh_seeds/metrics.csv"
#: DHRL and FLR+DHRL at the paper's update ratio (1 per env step), seeds 3000-3004, one GPU each.
PAPER_DHRL3, PAPER_FLR_DHRL3 = "ant3leg_paper_ratio/dhrl/metrics.csv", \
    "ant3leg_paper_ratio/flr_dhrl/metrics.csv"
#: Fig. 3 complete at 1.92M: DHRL (α = 0) and FLR+DHRL after 192, 96 and 48 initial random
#: episodes, seeds 5000-5004, one program each on the GPUs of one 4 x H200 host (commit e4906d8).
FIG3 = "fig3_1.92M/{}.csv"
#: Fig. 5 complete at 1.92M: α 0.001 / 0.1 (5c), ε 0.5 and the final goal as the next subgoal
#: (5a-b) and the DHRL (α = 0) / FLR+DHRL (α = 0.01, ε = 2) control, seeds 5000-5004, one
#: program each on the GPUs of one 4 x H100 host (commit 9705623).
FIG5 = "fig5_1.92M/{}.csv"
#: Fig. 2 right (the 4-legged ant) complete at 1.92M: DHRL (α = 0) / FLR+DHRL with 10 seeds
#: (5000-5009, two programs merged by merge_seeds.py), PIG and HIGL with 5 (5000-5004), one
#: program each on the GPUs of one 4 x H100 host (commit c96e72d).
FIG2_4LEG = "fig2_ant4leg_1.92M/{}.csv"
#: Fig. 2 left (the tripod) complete at 1.92M, one H100 per program: HIGL seeds 5000-5004 and
#: PIG / FLR+PIG seeds 5000-5001 and 5004 (commit 3585e01), 5002-5003 (31b0b5f, the same
#: ``flrjax/``), merged by merge_seeds.py; DHRL / FLR+DHRL is Fig. 5's program (``dhrl.csv``).
FIG2_3LEG = "fig2_ant3leg_1.92M/{}.csv"
#: DHRL (α = 0) and FLR+DHRL at the paper's update ratio in one program per seed, seeds
#: 5000-5003 one per GPU of a 4 x H100 host (commit 1cb92f8) and 5004 on one H100 (0f6d287,
#: the same training code), merged by merge_seeds.py; to 1.92M. (Seeds 5000-5003's first
#: run, H200s and commit 8eacb9f, was cut at 1.536M: ``paper_ratio_fresh/`` at commit eda542b.)
PAPER_FRESH = "paper_ratio_1.92M/dhrl.csv"
#: The same program with α = 0.005 (below 1 − γ) instead of 0.01, seeds 5000-5002 one per GPU
#: of a 4 x H200 host (commit cc09d40), merged by merge_seeds.py; to 1.92M.
PAPER_FRESH_A005 = "paper_ratio_1.92M_alpha0.005/alpha0.005.csv"
#: The same program with the low-level value ended at reaching (--low-value reach_ends), seeds
#: 9000-9003 one per GPU of a 4 x H200 host (commit 3235a42) and 9004 on another (0885866),
#: merged by merge_seeds.py; to 1.92M.
PAPER_REACH = "paper_ratio_reach_ends/reach.csv"
#: The same program with the k-step low-level value (--low-value k_step), seeds 9200-9203 one
#: per GPU of a 4 x H200 host (commit d548571) and 9204 on another (0885866), merged by
#: merge_seeds.py; to 1.92M.
PAPER_KSTEP = "paper_ratio_k_step/kstep.csv"
#: The figure protocol's DHRL / FLR+DHRL pair with --low-value reach_ends, seeds 9100-9104 in
#: one program on one H200 (commit 0885866); to 1.92M.
FIG_REACH = "fig_protocol_reach_ends/fig_reach.csv"
A005 = (("flr_alpha", "0.005"),)
#: FLR+DHRL at the paper's update ratio with α below 1 − γ, the same seeds, one GPU each.
PAPER_A005, PAPER_A002 = "ant3leg_paper_ratio/flr_dhrl_alpha_0.005/metrics.csv", \
    "ant3leg_paper_ratio/flr_dhrl_alpha_0.002/metrics.csv"

S_3LEG = ("\"FLR demonstrates superior performance in AntMaze3Leg\" (§3.2); "
          "FLR+DHRL \"outperforms all baselines in both environments\"")
S_4LEG = "\"Even in AntMaze4Leg [...] our framework exhibits slight gains in performance\" (§3.2)"
S_PIG = "\"FLR improves the performance of the vanilla PIG\" in AntMaze3Leg (§3.2, Fig. 2)"
S_FALLS = ("\"both PIG and DHRL experienced a substantial number of episodes where the agent "
           "falls, and FLR can always improve the situation\" (Fig. 4a, cumulative falls)")
S_GAP = ("\"FLR [is effective] in gradually penalizing fallen states as learning progresses\" "
         "(Fig. 4b, reward upright − fallen)")
S_ALPHA = "\"setting alpha to 0.01 = 1 − γ results in the best performance\" (Fig. 5c)"
S_NEXT_DHRL = ("\"any method of selecting the next sub-goal that is more than 2δ away [...] "
               "outperforms DHRL\" (Fig. 5a)")
S_NEXT_CLOSE = ("\"the method selecting closed subgoals demonstrates comparable or marginally "
                "inferior performance\" [to DHRL] (Fig. 5a)")
S_NEXT_EPS = ("ε = 2 (> 2δ) \"outperforms DHRL\" while \"the method selecting closed "
              "subgoals [ε = 0.5 = δ] demonstrates comparable or marginally inferior "
              "performance\" (Fig. 5a)")
S_NEXT_GOAL = ("\"selecting the final goal as the next sub-goal results in relatively lower "
               "performance\" [than ε = 2] (Fig. 5a)")
S_NEXT_GAP = ("\"selecting too far or near the next subgoal does not make the low-level policy "
              "distinguish the fallen states\" (Fig. 5b)")
S_BURN_FLR = ("\"our framework demonstrates robust learning, even when starting with less "
              "exploratory trajectories\" (Fig. 3)")
S_BURN_DHRL = "\"a vanilla DHRL requires a much longer burn-in period\" (Fig. 3)"
S_SURGE = "\"the success rate of PIG surges after 1M timesteps in AntMaze4Leg\" (Fig. 2 caption)"
S_4LEG_FALLS = ("\"in AntMaze4Leg [...] the chances of falling are relatively lower\" (§3.2)")

#: What every run shares that the paper does not state or defines otherwise.
CRITIC = ("an infinite-horizon low-level TD3 critic that never terminates (the paper defines "
          "the low-level value V^l as a k-step sum)")
FAST = "0.25 updates per env step (the paper states no ratio) and " + CRITIC
PAPER_RATIO = ("1 update per env step (DHRL's reference code; the paper states no ratio) and "
               + CRITIC)
REACH_ENDS = ("1 update per env step (DHRL's reference code; the paper states no ratio) and a "
              "low-level value that ends where a subgoal is reached (--low-value reach_ends: one "
              "reading of the paper's k-step V^l, without its bound of k steps)")
K_STEP = ("1 update per env step (DHRL's reference code; the paper states no ratio) and a "
          "low-level value summed over the subgoal's k steps, the critic seeing the steps left "
          "(--low-value k_step: the paper's k-step V^l)")
FAST_REACH = ("0.25 updates per env step (the paper states no ratio) and a low-level value that "
              "ends where a subgoal is reached (--low-value reach_ends: one reading of the "
              "paper's k-step V^l, without its bound of k steps)")
NO_A005, NO_A002 = (f"the paper tried α = 0.001, 0.01 and 0.1 (Fig. 5c), never {a}"
                    for a in ("0.005", "0.002"))
ROBUST = ("the paper claims robust learning with fewer initial episodes, against DHRL's longer "
          "burn-in, not an unchanged success rate: \"not below\" is a stricter reading (see "
          "\"FLR+DHRL > DHRL with 48 initial episodes\")")


def _paper_ratio_1_92m(csv: str, label: str, flr: tuple, alpha: str,
                       half_way: bool = False, beyond: str | None = None) -> list[Claim]:
    """The claims one paper-ratio program per seed to 1.92M tests (``csv``: DHRL as its α = 0
    point, FLR+DHRL as ``flr``): success, with ``half_way`` also success at 0.96M, falls and
    the reward gap's growth; ``alpha`` names a non-default α in the claims' names, ``beyond``
    why the paper made no claim on it."""
    name = f"the paper's update ratio, {alpha}fresh seeds"
    half = {"frac": 0.5}
    return [
        Claim(f"FLR+DHRL > DHRL, ant3leg, {name} in one program, 1.92M", S_3LEG,
              "success_rate", Arm(label, csv, flr), Arm("DHRL", csv, A0),
              min_step=FIGURE_STEPS, beyond=beyond),
        *([Claim(f"FLR+DHRL > DHRL, ant3leg, {name} in one program, half-way (0.96M)", S_3LEG,
                 "success_rate", Arm(label, csv, flr, **half), Arm("DHRL", csv, A0, **half),
                 min_step=FIGURE_STEPS, beyond=beyond)] if half_way else []),
        Claim(f"FLR reduces falls: FLR+DHRL < DHRL, ant3leg, {name} in one program, 1.92M",
              S_FALLS, "falls", Arm(label, csv, flr), Arm("DHRL", csv, A0), "<",
              cumulative=True, min_step=FIGURE_STEPS, beyond=beyond),
        Claim(f"reward gap grows, FLR+DHRL ant3leg, {name}, 1.92M: end vs half-way", S_GAP,
              "reward_gap", Arm("FLR+DHRL, end", csv, flr),
              Arm("FLR+DHRL, half-way", csv, flr, **half), trend=True, min_step=FIGURE_STEPS,
              beyond=beyond),
    ]


def _protocol(claim: Claim) -> Claim:
    """The claim with how its runs' protocol differs from the paper's: the paper-ratio runs
    (1 update per env step; with the value ended at reaching, or summed over k steps) or the
    fast protocol of every other run."""
    paper = {PAPER_DHRL3, PAPER_FLR_DHRL3, PAPER_A005, PAPER_A002, PAPER_FRESH, PAPER_FRESH_A005}
    ratio = claim.a.csv in paper or claim.b.csv in paper
    reach = PAPER_REACH in (claim.a.csv, claim.b.csv)
    k_step = PAPER_KSTEP in (claim.a.csv, claim.b.csv)
    fig_reach = FIG_REACH in (claim.a.csv, claim.b.csv)
    return dataclasses.replace(claim, differs=K_STEP if k_step else REACH_ENDS if reach
                               else FAST_REACH if fig_reach else PAPER_RATIO if ratio
                               else FAST)


def claims() -> list[Claim]:
    """The paper's testable claims, each with the committed CSVs that test it (see
    ``experiments/results/README.md`` for which directory holds which run)."""
    nxt, alpha, ctl = (FIG5.format(r) for r in ("flr_dhrl_next", "flr_dhrl_alpha", "dhrl"))
    eps05, goal = (("flr_next", "sample"), ("flr_eps", "0.5")), (("flr_next", "goal"),)
    dhrl4, pig4, higl4 = (FIG2_4LEG.format(r) for r in ("dhrl", "pig", "higl"))
    left_dhrl, left_pig, left_higl = (FIG2_3LEG.format(r) for r in ("dhrl", "pig", "higl"))
    init192, init96, init48 = (FIG3.format(r) for r in ("dhrl", "initial_96", "initial_48"))
    return [_protocol(c) for c in [
        Claim("FLR+DHRL > DHRL, ant3leg", S_3LEG, "success_rate",
              Arm("FLR+DHRL", FLR_DHRL3), Arm("DHRL", DHRL3)),
        Claim("FLR+DHRL > DHRL, ant3leg, fresh seeds in one program", S_3LEG, "success_rate",
              Arm("FLR+DHRL", FRESH3, A01), Arm("DHRL", FRESH3, A0)),
        Claim("FLR+DHRL > DHRL, ant3leg, the paper's update ratio (1 per env step)", S_3LEG,
              "success_rate", Arm("FLR+DHRL", PAPER_FLR_DHRL3), Arm("DHRL", PAPER_DHRL3)),
        Claim("FLR+DHRL > DHRL, ant3leg, the paper's update ratio, α = 0.005 (below 1 − γ)",
              S_3LEG, "success_rate", Arm("FLR+DHRL, α = 0.005", PAPER_A005),
              Arm("DHRL", PAPER_DHRL3), beyond=NO_A005),
        Claim("FLR+DHRL > DHRL, ant4leg (\"slight gains\"), 10 seeds", S_4LEG,
              "success_rate", Arm("FLR+DHRL", dhrl4, A01), Arm("DHRL", dhrl4, A0),
              min_step=FIGURE_STEPS),
        Claim("FLR+PIG > PIG, ant3leg (no subgoal skipping)", S_PIG, "success_rate",
              Arm("FLR+PIG", FLR_PIG3), Arm("PIG", PIG3)),
        Claim("FLR+PIG > PIG, ant3leg (subgoal skipping)", S_PIG, "success_rate",
              Arm("FLR+PIG", left_pig, A01), Arm("PIG", left_pig, A0), min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > HIGL, ant3leg", S_3LEG, "success_rate",
              Arm("FLR+DHRL", left_dhrl, A01), Arm("HIGL", left_higl), min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > PIG (following its planner), ant4leg",
              "FLR+DHRL \"outperforms all baselines in both environments\"; \"only DHRL can "
              "effectively accomplish the final goal\" in AntMaze4Leg (§3.2)", "success_rate",
              Arm("FLR+DHRL", dhrl4, A01), Arm("PIG", pig4), min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > PIG (policy alone, without its planner), ant4leg",
              "FLR+DHRL \"outperforms all baselines in both environments\" (§3.2)",
              "success_rate", Arm("FLR+DHRL", dhrl4, A01),
              Arm("PIG, policy alone", pig4, metric="no_plan_success_rate"),
              min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > HIGL, ant4leg",
              "FLR+DHRL \"outperforms all baselines in both environments\" (§3.2)",
              "success_rate", Arm("FLR+DHRL", dhrl4, A01), Arm("HIGL", higl4),
              min_step=FIGURE_STEPS),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg", S_FALLS, "falls",
              Arm("FLR+DHRL", FLR_DHRL3), Arm("DHRL", DHRL3), "<", cumulative=True),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg, fresh seeds in one program",
              S_FALLS, "falls", Arm("FLR+DHRL", FRESH3, A01), Arm("DHRL", FRESH3, A0), "<",
              cumulative=True),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg, the paper's update ratio",
              S_FALLS, "falls", Arm("FLR+DHRL", PAPER_FLR_DHRL3), Arm("DHRL", PAPER_DHRL3),
              "<", cumulative=True),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg, the paper's update ratio, "
              "α = 0.005", S_FALLS, "falls", Arm("FLR+DHRL, α = 0.005", PAPER_A005),
              Arm("DHRL", PAPER_DHRL3), "<", cumulative=True, beyond=NO_A005),
        Claim("FLR reduces falls: FLR+PIG < PIG, ant3leg (no skipping)", S_FALLS, "falls",
              Arm("FLR+PIG", FLR_PIG3), Arm("PIG", PIG3), "<", cumulative=True),
        Claim("FLR reduces falls: FLR+PIG < PIG, ant3leg (subgoal skipping)", S_FALLS, "falls",
              Arm("FLR+PIG", left_pig, A01), Arm("PIG", left_pig, A0), "<", cumulative=True,
              min_step=FIGURE_STEPS),
        Claim("falls rarer on ant4leg than ant3leg (DHRL)", S_4LEG_FALLS, "falls",
              Arm("DHRL ant4leg", dhrl4, A0), Arm("DHRL ant3leg", ctl, A0), "<",
              cumulative=True, min_step=FIGURE_STEPS),
        Claim("reward gap grows, FLR+DHRL ant3leg: end vs half-way", S_GAP, "reward_gap",
              Arm("FLR+DHRL, end", FLR_DHRL3), Arm("FLR+DHRL, half-way", FLR_DHRL3, frac=0.5),
              trend=True),
        Claim("reward gap grows, FLR+DHRL ant3leg, the paper's update ratio: end vs half-way",
              S_GAP, "reward_gap", Arm("FLR+DHRL, end", PAPER_FLR_DHRL3),
              Arm("FLR+DHRL, half-way", PAPER_FLR_DHRL3, frac=0.5), trend=True),
        Claim("reward gap grows, FLR+PIG ant3leg: end vs half-way", S_GAP, "reward_gap",
              Arm("FLR+PIG, end", FLR_PIG3), Arm("FLR+PIG, half-way", FLR_PIG3, frac=0.5),
              trend=True),
        Claim("α = 0.01 > α = 0.001", S_ALPHA, "success_rate", Arm("α = 0.01", ctl, A01),
              Arm("α = 0.001", alpha, (("flr_alpha", "0.001"),)), min_step=FIGURE_STEPS),
        Claim("α = 0.01 > α = 0.1", S_ALPHA, "success_rate", Arm("α = 0.01", ctl, A01),
              Arm("α = 0.1", alpha, (("flr_alpha", "0.1"),)), min_step=FIGURE_STEPS),
        Claim("α = 0.01 > α = 0.005, the paper's update ratio", S_ALPHA, "success_rate",
              Arm("α = 0.01", PAPER_FLR_DHRL3), Arm("α = 0.005", PAPER_A005), beyond=NO_A005),
        Claim("α = 0.01 > α = 0.002, the paper's update ratio", S_ALPHA, "success_rate",
              Arm("α = 0.01", PAPER_FLR_DHRL3), Arm("α = 0.002", PAPER_A002), beyond=NO_A002),
        Claim("ε = 2 > ε = 0.5", S_NEXT_EPS, "success_rate",
              Arm("ε = 2", ctl, A01), Arm("ε = 0.5", nxt, eps05), min_step=FIGURE_STEPS),
        Claim("ε = 2 > final goal as next subgoal", S_NEXT_GOAL, "success_rate",
              Arm("ε = 2", ctl, A01), Arm("final goal", nxt, goal), min_step=FIGURE_STEPS),
        Claim("final goal as next subgoal > DHRL", S_NEXT_DHRL, "success_rate",
              Arm("final goal", nxt, goal), Arm("DHRL", ctl, A0), min_step=FIGURE_STEPS),
        Claim("ε = 0.5 not above DHRL", S_NEXT_CLOSE, "success_rate",
              Arm("ε = 0.5", nxt, eps05), Arm("DHRL", ctl, A0), "<=", min_step=FIGURE_STEPS),
        Claim("reward gap: ε = 2 > ε = 0.5", S_NEXT_GAP, "reward_gap",
              Arm("ε = 2", ctl, A01), Arm("ε = 0.5", nxt, eps05), min_step=FIGURE_STEPS),
        Claim("reward gap: ε = 2 > final goal", S_NEXT_GAP, "reward_gap",
              Arm("ε = 2", ctl, A01), Arm("final goal", nxt, goal), min_step=FIGURE_STEPS),
        Claim("FLR+DHRL robust to 96 initial episodes (not below 192)", S_BURN_FLR,
              "success_rate", Arm("FLR+DHRL, 96", init96, A01),
              Arm("FLR+DHRL, 192", init192, A01), ">=", reading=ROBUST),
        Claim("FLR+DHRL robust to 48 initial episodes (not below 192)", S_BURN_FLR,
              "success_rate", Arm("FLR+DHRL, 48", init48, A01),
              Arm("FLR+DHRL, 192", init192, A01), ">=", reading=ROBUST),
        Claim("FLR+DHRL > DHRL with 48 initial episodes", S_BURN_FLR, "success_rate",
              Arm("FLR+DHRL, 48", init48, A01),
              Arm("DHRL, 48", init48, A0)),
        Claim("DHRL needs the longer burn-in: 192 > 48 initial episodes", S_BURN_DHRL,
              "success_rate", Arm("DHRL, 192", init192, A0),
              Arm("DHRL, 48", init48, A0)),
        Claim("PIG surges after 1M, ant4leg (following its planner): end vs up to 1M", S_SURGE,
              "success_rate", Arm("PIG, end", pig4),
              Arm("PIG, up to 1M", pig4, upto=1_000_000), min_step=FIGURE_STEPS),
        Claim("PIG surges after 1M, ant4leg (policy alone): end vs up to 1M", S_SURGE,
              "no_plan_success_rate", Arm("PIG, end", pig4),
              Arm("PIG, up to 1M", pig4, upto=1_000_000), min_step=FIGURE_STEPS),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant4leg, 10 seeds", S_FALLS, "falls",
              Arm("FLR+DHRL", dhrl4, A01), Arm("DHRL", dhrl4, A0), "<", cumulative=True,
              min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > DHRL, ant3leg, at the figures' 1.92M (Fig. 3's 192-episode run)",
              S_3LEG, "success_rate", Arm("FLR+DHRL", init192, A01),
              Arm("DHRL", init192, A0), min_step=FIGURE_STEPS),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg, at the figures' 1.92M", S_FALLS,
              "falls", Arm("FLR+DHRL", init192, A01),
              Arm("DHRL", init192, A0), "<", cumulative=True,
              min_step=FIGURE_STEPS),
        *_paper_ratio_1_92m(PAPER_FRESH, "FLR+DHRL", A01, ""),
        *_paper_ratio_1_92m(PAPER_FRESH_A005, "FLR+DHRL, α = 0.005", A005, "α = 0.005, ",
                            half_way=True, beyond=NO_A005),
        *_paper_ratio_1_92m(PAPER_REACH, "FLR+DHRL", A01, "reach ends, "),
        Claim("α = 0.01 > α = 0.005, the paper's update ratio, fresh seeds, 1.92M", S_ALPHA,
              "success_rate", Arm("α = 0.01", PAPER_FRESH, A01),
              Arm("α = 0.005", PAPER_FRESH_A005, A005), min_step=FIGURE_STEPS, beyond=NO_A005),
        Claim("FLR+DHRL > PIG (following its planner), ant3leg", S_3LEG, "success_rate",
              Arm("FLR+DHRL", left_dhrl, A01), Arm("PIG", left_pig, A0), min_step=FIGURE_STEPS),
        Claim("FLR+DHRL > PIG (policy alone, without its planner), ant3leg", S_3LEG,
              "success_rate", Arm("FLR+DHRL", left_dhrl, A01),
              Arm("PIG, policy alone", left_pig, A0, metric="no_plan_success_rate"),
              min_step=FIGURE_STEPS),
        Claim("reward gap grows, FLR+PIG ant3leg (subgoal skipping), 1.92M: end vs half-way",
              S_GAP, "reward_gap", Arm("FLR+PIG, end", left_pig, A01),
              Arm("FLR+PIG, half-way", left_pig, A01, frac=0.5), trend=True,
              min_step=FIGURE_STEPS),
        *_paper_ratio_1_92m(PAPER_KSTEP, "FLR+DHRL", A01, "k-step value, "),
        Claim("FLR+DHRL > DHRL, ant3leg, figure protocol, reach ends, fresh seeds in one "
              "program, 1.92M", S_3LEG, "success_rate", Arm("FLR+DHRL", FIG_REACH, A01),
              Arm("DHRL", FIG_REACH, A0), min_step=FIGURE_STEPS),
        Claim("FLR reduces falls: FLR+DHRL < DHRL, ant3leg, figure protocol, reach ends, "
              "1.92M", S_FALLS, "falls", Arm("FLR+DHRL", FIG_REACH, A01),
              Arm("DHRL", FIG_REACH, A0), "<", cumulative=True, min_step=FIGURE_STEPS),
    ]]


# ---------------------------------------------------------------- the table

def _m(step: int) -> str:
    """1824000 -> 1.824M, 48000 -> 48k: exact, as the CSVs' steps are multiples of 1000."""
    if step < 1_000:
        return str(step)
    if step < 1_000_000:
        return f"{step / 1e3:g}k"
    return f"{step / 1e6:.3f}".rstrip("0").rstrip(".") + "M"


def _num(x: float, digits: int, sign: bool = False) -> str:
    """``x`` to ``digits`` places; a value that rounds to zero prints as 0, not -0."""
    x = x if round(x, digits) != 0 else 0.0
    return f"{x:+.{digits}f}" if sign else f"{x:.{digits}f}"


def _device(info: RunInfo) -> str:
    return info.device.replace("NVIDIA ", "").replace(" 80GB HBM3", "")


def _where(where: Sequence[tuple[str, str]]) -> str:
    return (" " + ",".join(f"{k}={v}" for k, v in where)) if where else ""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def our_number(res: Result) -> str:
    """Mean ± sample std per arm, then the difference with its bootstrap 95% interval."""
    c = res.claim
    d = DIGITS.get(c.metric, 2)
    parts = []
    for arm, vals in zip((c.a, c.b), res.values, strict=True):
        v = list(vals.values())
        own = f" (`{arm.metric}`)" if arm.metric and arm.metric != c.metric else ""
        parts.append(f"{arm.label}{own} {_num(np.mean(v), d)} ± {_num(sample_std(v), d)}")
    lo, hi = res.ci
    return (f"`{c.metric}`{' (cumulative per seed)' if c.cumulative else ''}: "
            + "; ".join(parts) + f"; difference {_num(res.diff, d, True)} "
            f"(bootstrap 95% CI {_num(lo, d, True)} to {_num(hi, d, True)}; n = "
            f"{len(res.values[0])} vs {len(res.values[1])} seeds)")


def window_cell(res: Result) -> str:
    """The steps each arm's values cover, and where its rows come from."""
    c = res.claim
    what = "all evaluations" if c.cumulative else f"last {c.k} evaluations"
    out = []
    for arm, w, got, info in zip((c.a, c.b), res.windows, res.reached, res.info, strict=True):
        src = f"`{os.path.dirname(arm.csv) if arm.csv.endswith('metrics.csv') else arm.csv}`"
        src += _where(arm.where)
        if info.origin:
            src += f" (adopted from `{info.origin}`)"
        out.append(f"{arm.label}: {_m(w[0])}–{_m(w[1])}, {src}, reached {_m(got)}, "
                   f"{_device(info)}")
    same = all(not a.upto and a.frac == 1.0 for a in (c.a, c.b))
    head = f"{what}, common step {_m(res.common)}" if same else what
    return head + "; " + "; ".join(out)


def _p(p: float) -> str:
    return f"{p:.1e}" if p < 0.001 else f"{p:.3f}"


def p_cell(res: Result) -> str:
    """The raw p (how many splits or sign flips are as extreme, of how many) and Holm's."""
    if math.isnan(res.p):
        return "—"
    na, nb = res.n
    holm_p = "" if math.isnan(res.p_holm) else f"; Holm {_p(res.p_holm)}"
    if not res.exact:
        return f"{_p(res.p)} ({PERMUTATIONS:,} permutations){holm_p}"
    total = 2**na if res.claim.paired else n_splits(na, nb)
    kind = "paired, exact" if res.claim.paired else "exact"
    return f"{_p(res.p)} = {round(res.p * total):,}/{total:,} ({kind}){holm_p}"


def build_table(claim_list: Sequence[Claim], root: str = ROOT) -> list[Result]:
    """Evaluate every claim against the CSVs under ``root``, then judge each tested one by its
    Holm-adjusted p over the family of all of them."""
    results = [evaluate(c, root) for c in claim_list]
    family = [r for r in results if r.in_family]
    for r, p in zip(family, holm([r.p for r in family]), strict=True):
        judge(r, p)
    return results


def markdown_table(results: Sequence[Result]) -> str:
    """claim | paper's statement | our number | steps and runs | p | verdict."""
    lines = ["| # | claim | paper's statement | our number (mean ± sample std over seeds) | "
             "step window and runs | p: raw; Holm-adjusted | verdict |",
             "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(results, 1):
        testable = not math.isnan(r.diff)
        verdict_text = f"**{r.verdict}**" + "".join(f"; {n}" for n in r.judged + r.notes)
        lines.append("| " + " | ".join(_cell(x) for x in (
            str(i), r.claim.name, r.claim.statement, our_number(r) if testable else "—",
            window_cell(r) if testable else "—", p_cell(r), verdict_text)) + " |")
    return "\n".join(lines)


def caveats(results: Sequence[Result], root: str = ROOT) -> list[str]:
    """Notes drawn from the data: runs cut short of the figures' budget, control runs that
    several claims share, and comparisons across devices or runs."""
    out = []
    sources: dict[tuple[str, tuple[tuple[str, str], ...]], tuple[int, RunInfo, Arm]] = {}
    for r in results:
        if math.isnan(r.diff):
            continue
        for arm, got, info in zip((r.claim.a, r.claim.b), r.reached, r.info, strict=True):
            sources.setdefault((arm.csv, arm.where), (got, info, arm))
    short: dict[str, tuple[int, RunInfo]] = {}
    for got, info, arm in sources.values():
        if got < FIGURE_STEPS:
            short[arm.csv] = min(short.get(arm.csv, (got, info)), (got, info),
                                 key=lambda gi: gi[0])
    if short:
        items = [f"`{c}` at {_m(g)}" + (f" of {_m(i.planned)} planned" if i.planned else "")
                 + (" (a copy cut at the FLR+DHRL run's last step)" if i.origin else "")
                 for c, (g, i) in sorted(short.items())]
        out.append(f"Runs cut short of the figures' {_m(FIGURE_STEPS)} steps (last step "
                   "reached by every seed): " + "; ".join(items) + ". Claims on them are "
                   "tested at the common step, not at the paper's horizon.")
    longer = sorted({(arm.csv, got) for got, _, arm in sources.values() if got > FIGURE_STEPS})
    if longer:
        out.append("Runs past 1.92M, cut at the common step when compared: "
                   + "; ".join(f"`{c}` to {_m(g)}" for c, g in longer) + ".")
    origins: dict[str, list[int]] = {}
    for i, r in enumerate(results, 1):
        if math.isnan(r.diff):
            continue
        for arm, info in zip((r.claim.a, r.claim.b), r.info, strict=True):
            src = info.origin or (os.path.dirname(arm.csv) if arm.csv.endswith("metrics.csv")
                                  else None)
            if src and _in_shared_pair(src):
                origins.setdefault(src, []).append(i)
    if origins:
        copies = sorted({f"`{a.csv}`" for _, info, a in sources.values()
                         if info.origin and _in_shared_pair(info.origin)})
        used = sorted({i for v in origins.values() for i in v})
        copied = ("" if not copies else ": " + ", ".join(copies)
                  + (" are copies" if len(copies) > 1 else " is a copy")
                  + " of it (`figures.py --adopt`)")
        out.append(f"One DHRL/FLR+DHRL pair (`{SHARED_PAIR}/`, 5 seeds each) is the "
                   "control or the FLR point of several figures" + copied + ". Claims "
                   + ", ".join(map(str, used)) + " all rest on it, so they are not independent "
                   "evidence: one unlucky set of its seeds would move them all.")
    tested = [r for r in results if not math.isnan(r.diff)]
    mixed = [f"{i} ({_device(r.info[0])}, {r.n[0]} seeds, against {_device(r.info[1])}, "
             f"{r.n[1]} seeds)" for i, r in enumerate(results, 1)
             if r in tested and r.info[0].device != r.info[1].device]
    if mixed:
        devs = sorted({_device(i) for r in tested for i in r.info})
        out.append("Mixed devices (" + ", ".join(devs) + "): in claim"
                   + ("s " if len(mixed) > 1 else " ")
                   + ", ".join(map(str, mixed)) + " the two arms ran on different GPUs (and "
                   "in separate runs); the same seed on another GPU or in another run is "
                   "another sample, not a paired one, so only seed-to-seed spread is compared.")
    unequal = [f"{i} ({r.n[0]} against {r.n[1]} seeds)" for i, r in enumerate(results, 1)
               if r in tested and r.n[0] != r.n[1]]
    if unequal:
        out.append("Unequal seeds: claim" + ("s " if len(unequal) > 1 else " ")
                   + ", ".join(unequal) + "; the permutation test allows it, but the "
                   "smaller arm's spread is poorly known.")
    within = [i for i, r in enumerate(results, 1) if r in tested and r.claim.paired]
    if within:
        out.append("Claims " + ", ".join(map(str, within)) + " compare two windows of the same "
                   "seeds, so they use the paired sign-flip test, which "
                   + ", ".join(f"over {n} seeds cannot give p < {2 / 2**n:g} (2/{2**n})"
                               for n in sorted({results[i - 1].n[0] for i in within},
                                               reverse=True))
                   + ": at these seeds they are not testable at the 0.05 level and stay "
                   "outside Holm's family; the table gives each one's paired p and how many "
                   "seeds moved the paper's way.")
    family = [r for r in results if r.in_family]
    if family:
        below = sum(r.p < 2 / 252 for r in family)  # ranked ahead of a 2/252
        floor = min(1.0, (len(family) - below) * 2 / 252)
        out.append(f"Holm's correction runs over the {len(family)} claims that can reach "
                   f"p < {ALPHA:g}; a 5-against-5 claim's smallest raw p, 2/252, adjusts to at "
                   f"least {floor:.2f} here, so only claims with more seeds per arm can be "
                   "confirmed. The raw p is beside it, and the verdict notes what the raw p "
                   "alone would say.")
    out.append("`success_rate` is the fraction of 10 evaluation episodes that reach the goal "
               "(steps of 0.1 per evaluation) and `falls` the number of them that end "
               "fallen.")
    out.append("\"Best\" claims (α, ε) hold only if each of their pairwise rows does (an "
               "intersection–union test). A *partly* on a \"not below\" claim is not evidence "
               "of equivalence: with 5 seeds per arm only large differences are detectable.")
    return out


def _rank(word: str) -> int:
    """Where a verdict word comes in the count line."""
    order = ("confirmed", "partly", "not confirmed", "contradicted", "differs",
             "beyond the paper")
    return order.index(word) if word in order else len(order)


def render(results: Sequence[Result], root: str = ROOT) -> str:
    """The whole markdown document."""
    counts: dict[str, int] = {}
    for r in results:
        key = r.verdict.split(":")[0].split(" under ")[0]
        counts[key] = counts.get(key, 0) + 1
    head = __doc__.split("\n\n", 2)[2]
    return "\n\n".join([
        "# The paper's claims against our committed results",
        "Generated by `python experiments/claims.py --out docs/claims.md` from the CSVs under "
        "`experiments/results/` (see its README for the runs); do not edit by hand.",
        head.strip(),
        "Verdicts: " + ", ".join(f"{counts[k]} {k}" for k in sorted(counts, key=_rank)) + ".",
        markdown_table(results),
        "## Caveats",
        "\n".join(f"- {c}" for c in caveats(results, root)),
    ]) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=ROOT, help="the results directory")
    ap.add_argument("--out", default=None, help="markdown file to write (default: print)")
    args = ap.parse_args(argv)
    text = render(build_table(claims(), args.root), args.root)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)
    else:
        print(text)


if __name__ == "__main__":
    main()
