"""thesis_lib.stats: rliable's definitions, checked against rliable 1.2.0's own output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thesis_lib import stats

# Scores drawn once and run through rliable 1.2.0 (pandas 2.3.3, arch 7.2.0, numpy 2.4.6) in a
# separate environment: aggregate_iqm, probability_of_improvement and get_interval_estimates
# (percentile, 20,000 stratified bootstrap replications).
REF = json.loads((Path(__file__).parent / "fixtures" / "rliable_reference.json").read_text())
X, Y = np.array(REF["x"]), np.array(REF["y"])
RL = REF["rliable_1_2_0"]


def test_point_estimates_equal_rliables():
    assert stats.iqm(X) == pytest.approx(RL["iqm_x"], rel=1e-12)
    assert stats.probability_of_improvement(X, Y) == pytest.approx(RL["pi"], rel=1e-12)


@pytest.mark.parametrize(
    ("name", "fn", "args"),
    [
        ("iqm_ci", stats.iqm, (X,)),
        ("mean_ci", stats.mean, (X,)),
        ("pi_ci", stats.probability_of_improvement, (X, Y)),
    ],
)
def test_stratified_intervals_agree_with_rliable_to_monte_carlo_error(name, fn, args):
    _, lo, hi = stats.bootstrap_ci(fn, *args, reps=20_000, seed=0)
    tol = 0.02 if name == "pi_ci" else 0.3  # two independent 20k-replication bootstraps
    assert lo == pytest.approx(RL[name][0], abs=tol)
    assert hi == pytest.approx(RL[name][1], abs=tol)


@pytest.mark.parametrize("shape", [(2, 1), (5, 1), (5, 4), (30, 2)])
@pytest.mark.parametrize("stat", [stats.mean, stats.iqm, stats.probability_of_improvement])
def test_batched_statistics_give_the_intervals_of_one_call_per_resample(stat, shape):
    """The vectorised statistics (``stats.BATCHED``) see the same resamples and give the same
    numbers, bit for bit: a study's verdicts do not move with the speed-up. Rounded scores make
    ties, which the probability of improvement counts as halves."""
    rng = np.random.default_rng(shape[0] * 10 + shape[1])
    x = np.round(rng.normal(size=shape) * 2)
    y = np.round(rng.normal(size=(shape[0] + 1, shape[1])) * 2)
    args = (x, y) if stat is stats.probability_of_improvement else (x,)
    one_by_one = stats.bootstrap_ci(stat, *args, reps=700, seed=3)
    assert stats.bootstrap_ci(stat, *args, reps=700, seed=3, batched=stats.BATCHED[stat]) == (
        one_by_one
    )


def test_mean_interval_is_the_bootstrap_of_the_mean_and_says_nan_under_two_values():
    v = [3.0, 1.0, 4.0, 1.0, 5.0]
    assert stats.mean_interval(v, reps=500, seed=2) == stats.bootstrap_ci(
        stats.mean, np.array(v)[:, None], reps=500, seed=2
    )
    assert all(np.isnan(x) for x in stats.mean_interval([]))
    m, lo, hi = stats.mean_interval([7.0])
    assert m == 7.0 and np.isnan(lo) and np.isnan(hi)
    with pytest.raises(ValueError, match="NaN or inf"):
        stats.mean_interval([1.0, np.nan])
    with pytest.raises(ValueError, match="batched must return 50 values"):
        stats.bootstrap_ci(stats.mean, np.ones((3, 1)), reps=50, batched=lambda a: a.mean())


def test_probability_of_improvement_by_hand():
    # pairs (x > y): 1:0 2:0.5 3:1 ... 4.5 of 9; second setting: x always better
    x = np.array([[1.0, 10.0], [2.0, 11.0], [3.0, 12.0]])
    y = np.array([[0.0, 0.0], [2.0, 1.0], [4.0, 2.0]])
    assert stats.probability_of_improvement(x, y) == pytest.approx((4.5 / 9 + 1.0) / 2)


def test_resampling_stays_within_each_setting():
    # one setting only ever scores 0, the other 100: any within-setting resample keeps the
    # mean at 50 exactly; resampling across settings would not
    m = np.array([[0.0, 100.0]] * 5)
    _, lo, hi = stats.bootstrap_ci(stats.mean, m, reps=500)
    assert lo == hi == 50.0


@pytest.mark.parametrize(
    ("lo", "hi", "claim", "margin", "expected"),
    [
        (0.5, 2.0, "superior", 0.0, "holds"),
        (-2.0, -0.5, "superior", 0.0, "fails"),
        (-1.0, 1.0, "superior", 0.0, "inconclusive"),
        (-0.4, 0.3, "superior", 0.5, "fails"),  # absent, interval too narrow to hide it
        (-0.4, 0.8, "superior", 0.5, "inconclusive"),
        (-0.4, 0.3, "noninferior", 0.5, "holds"),
        (-3.0, -0.6, "noninferior", 0.5, "fails"),
        (-0.7, 0.3, "noninferior", 0.5, "inconclusive"),
    ],
)
def test_verdict_rule(lo, hi, claim, margin, expected):
    assert stats.verdict(lo, hi, claim, margin) == expected


def test_verdict_rejects_bad_input():
    with pytest.raises(ValueError, match="bad interval"):
        stats.verdict(1.0, 0.0)
    with pytest.raises(ValueError, match="claim"):
        stats.verdict(0.0, 1.0, "better")  # type: ignore[arg-type]


def _rows(x: np.ndarray, y: np.ndarray) -> pd.DataFrame:
    out = []
    for name, m in (("HDT", x), ("DT", y)):
        for seed in range(m.shape[0]):
            for s in range(m.shape[1]):
                out.append({"method": name, "setting": f"s{s}", "seed": seed, "score": m[seed, s]})
    return pd.DataFrame(out)


def test_compare_on_tidy_rows():
    c = stats.compare(_rows(X, Y), "HDT", "DT", "score", reps=2_000)
    assert c.effect == pytest.approx(X.mean() - Y.mean())
    assert c.ci_low < c.effect < c.ci_high
    assert c.prob_improvement == pytest.approx(RL["pi"])
    assert (c.seeds, c.settings) == (5, 4)
    assert c.verdict == stats.verdict(c.ci_low, c.ci_high)
    same = stats.compare(_rows(X, X), "HDT", "DT", "score", reps=500)
    assert same.effect == 0.0 and same.prob_improvement == 0.5


def test_incomplete_grid_and_bad_scores_are_errors():
    rows = _rows(X, Y)
    with pytest.raises(ValueError, match="incomplete"):
        stats.compare(rows.drop(index=0), "HDT", "DT", "score")
    with pytest.raises(ValueError, match="no rows for method 'BC'"):
        stats.compare(rows, "BC", "DT", "score")
    with pytest.raises(ValueError, match="NaN"):
        stats.probability_of_improvement(np.array([[np.nan]]), np.array([[1.0]]))


def test_a_bad_row_is_named_by_its_task_and_what_is_wrong():
    rows = _rows(X, Y)
    rows["task_key"] = [f"k{i}" for i in range(len(rows))]
    nan = rows.copy()
    nan.loc[3, "score"] = np.nan  # HDT, seed 0, setting s3: the other seeds of s3 are there
    with pytest.raises(
        ValueError, match=r"HDT: the row of setting 's3' \(seed 0\) has no score .* \(task k3\)"
    ):
        stats.compare(nan, "HDT", "DT", "score", reps=100)
    text = rows.astype({"score": object})
    text.loc[3, "score"] = "n/a"
    with pytest.raises(ValueError, match=r"has score 'n/a', not a number \(task k3\)"):
        stats.compare(text, "HDT", "DT", "score", reps=100)
    no_seed = rows.astype({"seed": float})
    no_seed.loc[3, "seed"] = np.nan
    with pytest.raises(ValueError, match=r"the row of setting 's3' has no seed \(task k3\)"):
        stats.compare(no_seed, "HDT", "DT", "score", reps=100)
    with pytest.raises(
        ValueError, match=r"Expect the rows to have the column 'seed' \(`seed_col`\)"
    ):
        stats.compare(rows.drop(columns="seed"), "HDT", "DT", "score", reps=100)
    with pytest.raises(ValueError, match=r"incomplete: no row for \(setting, seed\) \('s0', 0\)"):
        stats.compare(rows.drop(index=0), "HDT", "DT", "score", reps=100)


@pytest.mark.parametrize("margin", ["half", -1.0, True, None])
def test_a_comparison_margin_must_be_a_number(margin):
    from thesis_lib.stats.claims import check_comparison

    spec = {"claim": "C3", "x": "HDT", "y": "DT", "margin": margin}
    with pytest.raises(ValueError, match=r"Expect `margin` of comparison C3 \(HDT vs DT\)"):
        check_comparison(spec)
    check_comparison({**spec, "margin": 2})  # an int is a number


def test_performance_profile_counts_runs_above_each_threshold():
    share, lo, hi = stats.performance_profile(
        np.array([[1.0, 10.0], [2.0, 20.0]]), [0.0, 1.5, 15.0, 30.0], reps=500
    )
    # 4 scores: above 0: all; above 1.5: 2, 10, 20; above 15: 20; above 30: none
    assert share.tolist() == [1.0, 0.75, 0.25, 0.0]
    assert lo[0] == hi[0] == 1.0 and lo[-1] == hi[-1] == 0.0
    assert np.all(lo <= share) and np.all(share <= hi)


def test_aggregate_interval_matches_bootstrap_ci_and_rejects_unknown_aggregates():
    m = np.array([[1.0, 5.0], [2.0, 6.0], [3.0, 9.0]])
    assert stats.aggregate_interval(m, "mean", reps=300) == stats.bootstrap_ci(
        stats.mean, m, reps=300
    )
    with pytest.raises(ValueError, match="aggregate must be"):
        stats.aggregate_interval(m, "max")


def test_seeds_needed_matches_the_welch_interval_it_plans_for():
    """The seed count a pre-registration reads off ``seeds_needed`` gives, in simulation, the
    interval it promises: at that count the mean half-width of ``welch_interval`` is within a
    few percent of the target, and one seed fewer is wider."""
    from thesis_lib.stats import seeds_needed, welch_interval

    rng = np.random.default_rng(0)

    def half(k, sd, settings):
        widths = []
        for _ in range(400):
            x = rng.normal(0.0, sd, size=(k, settings))
            y = rng.normal(0.0, sd, size=(k, settings))
            _, lo, hi = welch_interval(x, y)
            widths.append((hi - lo) / 2)
        return float(np.mean(widths))

    for sd, target, settings in ((8.2, 5.0, 1), (8.2, 5.0, 11), (3.0, 2.0, 2)):
        n = seeds_needed(sd, target, settings=settings)
        assert half(n, sd, settings) <= target * 1.05, (sd, target, settings, n)
        if n > 2:
            assert half(n - 1, sd, settings) > half(n, sd, settings)
    assert seeds_needed(0.0, 1.0) == 2
    with pytest.raises(ValueError, match="settings >= 1"):
        seeds_needed(1.0, 1.0, settings=0)
    with pytest.raises(ValueError, match="More than 10 seeds"):
        seeds_needed(50.0, 1.0, max_seeds=10)
