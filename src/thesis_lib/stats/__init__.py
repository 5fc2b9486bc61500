"""The evidence rules of ``CLAIMS.md`` over tidy per-run rows.

Definitions are rliable's (Agarwal et al. 2021, "Deep RL at the edge of the statistical
precipice"), computed here with NumPy/SciPy and tested against rliable's own numbers on a
fixture (``tests/test_stats.py``):

- **IQM**: the mean of the middle 50% of all (run, setting) scores,
  ``scipy.stats.trim_mean(scores, 0.25)``.
- **Stratified bootstrap**: each method's runs are resampled with replacement *within each
  setting*, independently per method; the 95% interval is the percentile interval of the
  statistic over the resamples.
- **Probability of improvement** ``P(X > Y)``: per setting, the Mann-Whitney U statistic
  over all (x, y) pairs of runs divided by their number (ties count one half), averaged
  over settings.

Why not rliable itself: its last release (1.2.0) needs ``arch < 8``; ``arch`` 7.2 does not
import under the project's pandas 3.1 and ``arch`` 8 rejects rliable's ``random_state``.
Pinning pandas 2.3 for one statistics package would move the whole stack, so the same
definitions are written here (about 100 lines) and checked against rliable's output.

A comparison's **verdict** follows CLAIMS.md: *holds* when the interval excludes "no effect"
in the claimed direction; *fails* when it excludes it in the opposite direction, or when the
claimed effect is absent with an interval too narrow to hide it (inside ``±margin``, the
smallest effect that matters, fixed in the study's parameter file); *inconclusive* otherwise.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd
from scipy import stats as _st

Claim = Literal["superior", "noninferior", "equivalent"]
VERDICTS = ("holds", "fails", "inconclusive", "untestable")


def iqm(scores: np.ndarray | Sequence[float]) -> float:
    """Interquartile mean of all scores (rliable's ``aggregate_iqm``).

    >>> iqm([1, 2, 3, 4, 5, 6, 7, 100])
    4.5
    """
    return float(_st.trim_mean(np.asarray(scores, dtype=float).ravel(), 0.25))


def mean(scores: np.ndarray | Sequence[float]) -> float:
    """Mean of all scores."""
    return float(np.mean(np.asarray(scores, dtype=float)))


AGGREGATES: dict[str, Callable[[np.ndarray], float]] = {"mean": mean, "iqm": iqm}


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """``P(X > Y)`` for score matrices ``(runs, settings)``, averaged over settings.

    >>> probability_of_improvement(np.array([[1.0], [2.0], [3.0]]), np.array([[0.0], [2.0], [4.0]]))
    0.5
    """
    x, y = _matrix(x), _matrix(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x has {x.shape[1]} settings, y has {y.shape[1]}")
    diff = x[:, None, :] - y[None, :, :]  # (n_x, n_y, S)
    wins = (diff > 0).mean(axis=(0, 1)) + 0.5 * (diff == 0).mean(axis=(0, 1))
    return float(wins.mean())


def _matrix(a: Any) -> np.ndarray:
    m = np.asarray(a, dtype=float)
    if m.ndim == 1:
        m = m[:, None]
    if m.ndim != 2 or m.shape[0] == 0:
        raise ValueError(f"scores must be a (runs, settings) matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("scores contain NaN or inf")
    return m


def _resample(m: np.ndarray, rng: np.random.Generator, reps: int) -> np.ndarray:
    """``(reps, runs, settings)``: runs drawn with replacement within each setting."""
    n, s = m.shape
    idx = rng.integers(0, n, size=(reps, n, s))
    return np.take_along_axis(np.broadcast_to(m, (reps, n, s)), idx, axis=1)


def bootstrap_ci(
    stat: Callable[..., float],
    *matrices: np.ndarray,
    reps: int = 10_000,
    alpha: float = 0.05,
    seed: int = 0,
    batched: Callable[..., np.ndarray] | None = None,
) -> tuple[float, float, float]:
    """``(point, low, high)``: ``stat(*matrices)`` and its stratified percentile interval.

    Each ``(runs, settings)`` matrix is resampled independently, runs within settings.
    ``batched``, where given, is ``stat`` over a stack of resamples: it takes ``(reps, runs,
    settings)`` arrays and returns the ``reps`` values ``stat`` gives one by one (the same
    resamples, so the same interval; the module's own statistics have one, see
    :data:`BATCHED`), instead of a Python call per resample.
    """
    ms = [_matrix(m) for m in matrices]
    rng = np.random.default_rng(seed)
    point = float(stat(*ms))
    boots = [_resample(m, rng, reps) for m in ms]
    if batched is not None:
        vals = np.asarray(batched(*boots), dtype=float)
        if vals.shape != (reps,):
            raise ValueError(f"batched must return {reps} values, got shape {vals.shape}")
    else:
        vals = np.array([stat(*(b[r] for b in boots)) for r in range(reps)])
    lo, hi = np.percentile(vals, [100 * alpha / 2, 100 * (1 - alpha / 2)])
    return point, float(lo), float(hi)


def _batched_mean(a: np.ndarray) -> np.ndarray:
    return a.mean(axis=(1, 2))


def _batched_iqm(a: np.ndarray) -> np.ndarray:
    return _st.trim_mean(a.reshape(a.shape[0], -1), 0.25, axis=1)


def _batched_probability_of_improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    out = np.empty(x.shape[0])
    step = max(1, 2_000_000 // (x.shape[1] * y.shape[1] * x.shape[2]))  # ~16 MB a block
    for i in range(0, x.shape[0], step):
        diff = x[i : i + step, :, None, :] - y[i : i + step, None, :, :]  # (r, n_x, n_y, S)
        wins = (diff > 0).mean(axis=(1, 2)) + 0.5 * (diff == 0).mean(axis=(1, 2))
        out[i : i + step] = wins.mean(axis=1)
    return out


#: The module's statistics over a stack of resamples, for :func:`bootstrap_ci`'s ``batched``:
#: the same numbers as calling each on every resample (``tests/test_stats.py``), ten to a
#: hundred times sooner.
BATCHED: dict[Callable[..., float], Callable[..., np.ndarray]] = {
    mean: _batched_mean,
    iqm: _batched_iqm,
    probability_of_improvement: _batched_probability_of_improvement,
}


def mean_interval(
    values: np.ndarray | Sequence[float], reps: int = 2000, alpha: float = 0.05, seed: int = 0
) -> tuple[float, float, float]:
    """``(mean, low, high)`` of one sample of ``values`` (e.g. one per seed) with its
    percentile bootstrap interval; NaN bounds under two values (NaN throughout with none).

    >>> mean_interval([1.0, 2.0, 3.0, 4.0], reps=100)[0], mean_interval([5.0])
    (2.5, (5.0, nan, nan))
    """
    v = np.asarray(values, dtype=float).ravel()
    if len(v) < 2:
        return (float(v.mean()) if len(v) else np.nan), np.nan, np.nan
    return bootstrap_ci(mean, v[:, None], reps=reps, alpha=alpha, seed=seed, batched=_batched_mean)


def welch_test(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """``(effect, standard error, degrees of freedom)`` of the stratified mean difference of
    :func:`welch_interval`."""
    mx, my = _matrix(x), _matrix(y)
    if mx.shape[1] != my.shape[1]:
        raise ValueError(f"x and y have different settings: {mx.shape[1]} vs {my.shape[1]}")
    nx, ny, s = mx.shape[0], my.shape[0], mx.shape[1]
    if nx < 2 or ny < 2:
        raise ValueError("a Welch interval needs at least 2 runs of each method")
    effect = float((mx.mean(axis=0) - my.mean(axis=0)).mean())
    terms = np.concatenate([mx.var(axis=0, ddof=1) / nx, my.var(axis=0, ddof=1) / ny]) / s**2
    var = float(terms.sum())
    if var == 0.0:
        return effect, 0.0, float("inf")
    dfs = np.concatenate([np.full(s, nx - 1), np.full(s, ny - 1)])
    return effect, var**0.5, var**2 / float((terms**2 / dfs).sum())


def p_value(
    effect: float, se: float, df: float, claim: Claim = "superior", margin: float = 0.0
) -> float:
    """One-sided p of the claim against its null, from a t statistic: ``superior``
    ``H0: d <= 0``; ``noninferior`` ``H0: d <= -margin``; ``equivalent`` the larger p of the two
    one-sided tests ``H0: d <= -margin`` and ``H0: d >= margin`` (TOST).

    >>> round(p_value(2.0, 1.0, 10), 4), round(p_value(0.0, 1.0, 10, "equivalent", 3.0), 4)
    (0.0367, 0.0067)
    """
    if se == 0.0:
        lo_ok = effect > (0.0 if claim == "superior" else -margin)
        hi_ok = claim != "equivalent" or effect < margin
        return 0.0 if lo_ok and hi_ok else 1.0
    if claim == "superior":
        return float(_st.t.sf(effect / se, df))
    if claim == "noninferior":
        return float(_st.t.sf((effect + margin) / se, df))
    lower = float(_st.t.sf((effect + margin) / se, df))
    upper = float(_st.t.cdf((effect - margin) / se, df))
    return max(lower, upper)


def holm(pvalues: Sequence[float]) -> np.ndarray:
    """Holm's step-down adjustment of ``pvalues`` (NaN stays NaN and is left out of the family).

    >>> holm([0.01, 0.04, 0.03, float("nan")]).round(2).tolist()
    [0.03, 0.06, 0.06, nan]
    """
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    if not len(ok):
        return out
    order = ok[np.argsort(p[ok], kind="stable")]
    m = len(order)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return out


def welch_interval(x: np.ndarray, y: np.ndarray, alpha: float = 0.05) -> tuple[float, float, float]:
    """``(effect, low, high)``: the difference of stratified means ``mean(x) - mean(y)`` over
    ``(runs, settings)`` matrices (each setting weighted equally) with a Welch t interval.

    The effect is ``(1/S) sum_s (xbar_s - ybar_s)``; its variance
    ``(1/S^2) sum_s (v_xs / n_x + v_ys / n_y)`` (sample variances), and its degrees of freedom
    Welch-Satterthwaite's over all ``2 S`` terms. With 5 seeds a percentile bootstrap covers
    about 89% of the time; this interval keeps its 95% for normal scores (tested by
    simulation in ``tests/test_stats.py``).

    >>> e, lo, hi = welch_interval(np.array([[1.0], [2.0], [3.0]]), np.array([[0.0], [1.0], [2.0]]))
    >>> e, round(lo, 3), round(hi, 3)
    (1.0, -1.267, 3.267)
    """
    effect, se, df = welch_test(x, y)
    if se == 0.0:
        return effect, effect, effect
    half = float(_st.t.ppf(1 - alpha / 2, df)) * se
    return effect, effect - half, effect + half


def seeds_needed(
    sd: float, half_width: float, settings: int = 1, alpha: float = 0.05, max_seeds: int = 10_000
) -> int:
    """The fewest seeds per method and setting at which :func:`welch_interval` of a difference
    of stratified means over ``settings`` settings is expected to be at most ``half_width``
    wide on each side, when every run of either method scatters by ``sd`` around its setting's
    mean: a pre-registration's seed count (CLAIMS.md: 5, "more where the interval method
    needs them").

    The interval's half-width is ``t(1 - alpha/2, df) * sd * sqrt(2 / (settings * n))`` with
    Welch's ``df = 2 * settings * (n - 1)`` for equal spreads.

    >>> seeds_needed(8.2, 5.0), seeds_needed(8.2, 5.0, settings=11), seeds_needed(1.0, 5.0)
    (22, 3, 2)

    Raises:
        ValueError: If ``sd`` is negative, ``half_width`` or ``settings`` not positive, or no
            count up to ``max_seeds`` suffices.
    """
    if sd < 0 or half_width <= 0 or settings < 1:
        raise ValueError(
            f"Expect sd >= 0, half_width > 0 and settings >= 1, got {sd}, {half_width}, {settings}."
        )
    for n in range(2, max_seeds + 1):
        df = 2 * settings * (n - 1)
        if float(_st.t.ppf(1 - alpha / 2, df)) * sd * np.sqrt(2 / (settings * n)) <= half_width:
            return n
    raise ValueError(f"More than {max_seeds} seeds would be needed for sd {sd} at {half_width}.")


#: How :func:`compare` makes the effect's interval: ``welch`` (the default for the mean
#: aggregate: a t interval that keeps its coverage at the studies' 3-5 seeds) or ``bootstrap``
#: (rliable's stratified percentile bootstrap; the only one for IQM, and the v1 studies' rule).
INTERVALS = ("welch", "bootstrap")


def performance_profile(
    scores: np.ndarray | Sequence[float],
    taus: np.ndarray | Sequence[float],
    reps: int = 2000,
    alpha: float = 0.05,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rliable's run-score distribution (its "performance profile"): for each threshold
    ``tau``, the share of all (run, setting) scores above ``tau``, with a stratified
    bootstrap percentile interval.

    Returns ``(share, low, high)``, each of ``len(taus)``.

    >>> share, lo, hi = performance_profile([[1.0], [2.0], [3.0], [4.0]], [0.0, 2.5, 5.0])
    >>> share.tolist()
    [1.0, 0.5, 0.0]
    """
    m = _matrix(scores)
    t = np.asarray(taus, dtype=float).ravel()

    def profile(a: np.ndarray) -> np.ndarray:  # (..., runs, settings) -> (..., taus)
        return (a[..., None] > t).mean(axis=(-3, -2))

    boots = profile(_resample(m, np.random.default_rng(seed), reps))
    lo, hi = np.percentile(boots, [100 * alpha / 2, 100 * (1 - alpha / 2)], axis=0)
    return profile(m), lo, hi


def aggregate_interval(
    scores: np.ndarray | Sequence[float],
    aggregate: str = "iqm",
    reps: int = 2000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """``(point, low, high)``: one method's aggregate score over all (run, setting) scores
    with its 95% stratified bootstrap interval (rliable's ``get_interval_estimates``).

    >>> aggregate_interval([[1.0], [2.0], [3.0], [4.0]], "mean", reps=100)[0]
    2.5
    """
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {sorted(AGGREGATES)}, got {aggregate!r}")
    agg = AGGREGATES[aggregate]
    return bootstrap_ci(agg, _matrix(scores), reps=reps, seed=seed, batched=BATCHED[agg])


def verdict(ci_low: float, ci_high: float, claim: Claim = "superior", margin: float = 0.0) -> str:
    """The verdict of CLAIMS.md for an effect ``X - Y`` with interval ``[ci_low, ci_high]``.

    ``superior`` claims ``X > Y``: holds if ``ci_low > 0``; fails if ``ci_high < 0`` or the
    whole interval lies inside ``[-margin, margin]`` (no effect that matters).
    ``noninferior`` claims ``X >= Y - margin`` ("needs no RTG", "at least as good"): holds if
    ``ci_low > -margin``; fails if ``ci_high < -margin``.
    ``equivalent`` claims ``|X - Y| < margin`` ("about the same"), by two one-sided tests
    (TOST): give it the 90% interval; holds if it lies inside ``(-margin, margin)``, fails if
    it lies wholly outside.

    >>> verdict(0.5, 2.0), verdict(-2.0, -0.5), verdict(-1.0, 1.0)
    ('holds', 'fails', 'inconclusive')
    >>> verdict(-0.4, 0.3, margin=0.5), verdict(-0.4, 0.3, "noninferior", 0.5)
    ('fails', 'holds')
    """
    if not (np.isfinite(ci_low) and np.isfinite(ci_high)) or ci_low > ci_high:
        raise ValueError(f"bad interval [{ci_low}, {ci_high}]")
    if margin < 0:
        raise ValueError("margin must be >= 0")
    if claim == "superior":
        if ci_low > 0:
            return "holds"
        if ci_high < 0 or (margin > 0 and -margin <= ci_low and ci_high <= margin):
            return "fails"
        return "inconclusive"
    if claim == "noninferior":
        if ci_low > -margin:
            return "holds"
        if ci_high < -margin:
            return "fails"
        return "inconclusive"
    if claim == "equivalent":  # TOST: the (1 - 2 alpha) interval inside the band
        if -margin < ci_low and ci_high < margin:
            return "holds"
        if ci_low > margin or ci_high < -margin:
            return "fails"
        return "inconclusive"
    raise ValueError(f"claim must be 'superior', 'noninferior' or 'equivalent', got {claim!r}")


@dataclass
class Comparison:
    """One comparison of method ``x`` against method ``y`` over settings and seeds."""

    x: str
    y: str
    metric: str
    aggregate: str
    effect: float
    """``aggregate(x) - aggregate(y)``."""
    ci_low: float
    ci_high: float
    prob_improvement: float
    pi_low: float
    pi_high: float
    x_score: float
    y_score: float
    seeds: int
    settings: int
    kind: str
    """``superior`` or ``noninferior`` (see :func:`verdict`)."""
    margin: float
    verdict: str
    interval: str = "bootstrap"
    """How ``ci_low``/``ci_high`` were made (:data:`INTERVALS`); 90% for ``equivalent``."""
    p_value: float = float("nan")
    """One-sided p of the claim (:func:`p_value`; Welch intervals only, else NaN)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def score_matrix(
    rows: pd.DataFrame,
    method: str,
    metric: str,
    settings: Sequence[str] | None = None,
    method_col: str = "method",
    setting_col: str = "setting",
    seed_col: str = "seed",
) -> tuple[np.ndarray, list[str]]:
    """``(seeds, settings)`` matrix of ``metric`` for ``method`` from tidy rows.

    A row that is wrong is named by where it came from: its ``task_file`` column, else its
    ``task_key`` column (a study's rows have both), else its index.

    Raises:
        ValueError: a column is missing, the method is missing, a row has no seed or no number
            for ``metric`` (NaN, missing, text), a (setting, seed) appears twice, or settings
            have different seeds (the grid is incomplete: finish the study first).
    """
    _check_columns(rows, method_col=method_col, setting_col=setting_col, seed_col=seed_col)
    _check_columns(rows, metric=metric)
    sub = rows[rows[method_col] == method]
    if sub.empty:
        known = sorted(rows[method_col].unique())
        raise ValueError(f"no rows for method {method!r}; methods: {known}")
    if settings is not None:
        missing = [s for s in settings if s not in set(sub[setting_col])]
        if missing:
            raise ValueError(f"{method}: no rows for settings {missing}")
        sub = sub[sub[setting_col].isin(settings)]
    values = pd.to_numeric(sub[metric], errors="coerce").astype(float)
    bad = sub.index[sub[seed_col].isna() | ~np.isfinite(values)]
    if len(bad):
        r = {k: v.item() if isinstance(v, np.generic) else v for k, v in sub.loc[bad[0]].items()}
        if pd.isna(r[seed_col]):
            what = f"has no {seed_col}"
        elif pd.isna(r[metric]):
            what = f"({seed_col} {r[seed_col]!r}) has no {metric} (NaN or missing)"
        else:
            what = f"({seed_col} {r[seed_col]!r}) has {metric} {r[metric]!r}, not a number"
        raise ValueError(
            f"{method}: the row of {setting_col} {r[setting_col]!r} {what} ({_source(sub, bad[0])})"
        )
    if sub.duplicated([setting_col, seed_col]).any():
        raise ValueError(f"{method}: a (setting, seed) appears more than once")
    wide = sub.assign(**{metric: values}).pivot(index=seed_col, columns=setting_col, values=metric)
    if settings is not None:
        wide = wide[list(settings)]
    if wide.isna().any().any():
        counts = sub.groupby(setting_col)[seed_col].nunique().to_dict()
        absent = [f"({c!r}, {k!r})" for c in wide.columns for k in wide.index[wide[c].isna()]]
        raise ValueError(
            f"{method}: unequal seeds per setting {counts}; the grid is incomplete: no row for "
            f"({setting_col}, {seed_col}) {', '.join(absent)}"
        )
    return wide.to_numpy(dtype=float), [str(c) for c in wide.columns]


def _check_columns(rows: pd.DataFrame, **columns: str) -> None:
    """Each named column is in ``rows`` (``ValueError`` naming the parameter and the column)."""
    for name, col in columns.items():
        if col not in rows.columns:
            example = f" (e.g. {_source(rows, rows.index[0])})" if len(rows) else ""
            raise ValueError(
                f"Expect the rows to have the column {col!r} (`{name}`), actually: "
                f"{', '.join(map(str, rows.columns))}{example}"
            )


def _source(rows: pd.DataFrame, index: Any) -> str:
    """Where row ``index`` came from: its task file or task key, else its index."""
    for col, label in (("task_file", ""), ("task_key", "task ")):
        if col in rows.columns and isinstance(rows.at[index, col], str):
            return f"{label}{rows.at[index, col]}"
    return f"row {index}"


def shared_settings(
    rows: pd.DataFrame,
    x: str,
    y: str,
    metric: str,
    method_col: str = "method",
    setting_col: str = "setting",
) -> list[Any]:
    """The settings (sorted) where both ``x`` and ``y`` have ``metric``: those :func:`compare`
    uses when it is given none."""
    has = rows[rows[metric].notna()] if metric in rows else rows
    sx = set(has.loc[has[method_col] == x, setting_col])
    sy = set(has.loc[has[method_col] == y, setting_col])
    return sorted(sx & sy)


def compare(
    rows: pd.DataFrame,
    x: str,
    y: str,
    metric: str,
    *,
    settings: Sequence[str] | None = None,
    aggregate: str = "mean",
    claim: Claim = "superior",
    margin: float = 0.0,
    reps: int = 10_000,
    seed: int = 0,
    method_col: str = "method",
    setting_col: str = "setting",
    seed_col: str = "seed",
    interval: str = "bootstrap",
) -> Comparison:
    """Compare methods ``x`` and ``y`` on ``metric``: effect, interval, P(X > Y), verdict.

    The effect is ``aggregate(x) - aggregate(y)`` over all (seed, setting) scores of the
    settings both methods ran (``settings`` to choose), with a stratified bootstrap interval
    (``interval="bootstrap"``) or, for the mean, a Welch t interval (``"welch"``:
    :func:`welch_interval`, which keeps its coverage at few seeds).
    Without ``settings``, a setting counts where both methods have the metric (a study's
    timing rows and score rows can share the methods); a missing value there is an error.
    """
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {sorted(AGGREGATES)}, got {aggregate!r}")
    kw = dict(method_col=method_col, setting_col=setting_col, seed_col=seed_col)
    _check_columns(rows, **kw)
    _check_columns(rows, metric=metric)
    known = set(rows[method_col].unique())
    for m in (x, y):
        if m not in known:
            raise ValueError(f"no rows for method {m!r}; methods: {sorted(known)}")
    if settings is None:  # the settings where both methods have the metric
        settings = shared_settings(rows, x, y, metric, method_col, setting_col)
        if not settings:
            raise ValueError(f"{x} and {y} share no setting")
    mx, cols = score_matrix(rows, x, metric, settings, **kw)
    my, _ = score_matrix(rows, y, metric, settings, **kw)
    agg = AGGREGATES[aggregate]
    if interval not in INTERVALS:
        raise ValueError(f"interval must be one of {', '.join(INTERVALS)}, got {interval!r}")
    if interval == "welch" and aggregate != "mean":
        raise ValueError(f"a Welch interval is for the mean aggregate, not {aggregate!r}")
    # an equivalence claim is decided by TOST: its two one-sided 5% tests are the 90% interval
    alpha = 0.10 if claim == "equivalent" else 0.05
    p = float("nan")
    if interval == "welch":
        eff, lo, hi = welch_interval(mx, my, alpha=alpha)
        p = p_value(*welch_test(mx, my), claim=claim, margin=margin)
    else:
        bagg = BATCHED[agg]
        eff, lo, hi = bootstrap_ci(
            lambda a, b: agg(a) - agg(b),
            mx,
            my,
            reps=reps,
            seed=seed,
            alpha=alpha,
            batched=lambda a, b: bagg(a) - bagg(b),
        )
    pi, pl, ph = bootstrap_ci(
        probability_of_improvement,
        mx,
        my,
        reps=reps,
        seed=seed,
        batched=_batched_probability_of_improvement,
    )
    return Comparison(
        x=x,
        y=y,
        metric=metric,
        aggregate=aggregate,
        effect=eff,
        ci_low=lo,
        ci_high=hi,
        prob_improvement=pi,
        pi_low=pl,
        pi_high=ph,
        x_score=agg(mx),
        y_score=agg(my),
        seeds=int(min(mx.shape[0], my.shape[0])),
        settings=len(cols),
        kind=claim,
        margin=float(margin),
        verdict=verdict(lo, hi, claim, margin),
        interval=interval,
        p_value=p,
    )


__all__ = [
    "AGGREGATES",
    "BATCHED",
    "INTERVALS",
    "holm",
    "p_value",
    "welch_interval",
    "welch_test",
    "VERDICTS",
    "Comparison",
    "aggregate_interval",
    "bootstrap_ci",
    "compare",
    "iqm",
    "mean",
    "mean_interval",
    "performance_profile",
    "probability_of_improvement",
    "score_matrix",
    "seeds_needed",
    "shared_settings",
    "verdict",
]
