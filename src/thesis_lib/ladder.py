"""The scale ladder (issue #36): the cheapest model size at which the sequence-model studies
can show their effects, chosen before their second studies are pre-registered.

``thesis ladder`` reads the current ladder file (:data:`CURRENT_LADDER`,
``params/ladder.v2.yml``): data sets (D4RL's size), methods, seeds,
*rungs* (model sizes, cheapest first), *checkpoints* (updates) and the training and evaluation
every run shares. Each (data set, rung, method, seed) is one run (BC's, whose model no rung
sizes, one per data set and seed: :data:`RUNG_FREE_METHODS`), a
:class:`~thesis_lib.sweep.Task` trained once to the last checkpoint and evaluated at every
checkpoint (so the 10k and the 30k rungs of one size cost one 30k run), stored at once under
``studies/<file name>/tasks/`` (resumable, committed); :func:`ladder_table` is written to
``ladder.csv`` beside them.

The table holds, per data set x rung x checkpoint, each method's mean D4RL-normalised score of
the final evaluation over seeds with a 95% t interval, and the rung's verdicts:

* **level**: the file's ``relative_to`` method (BC) scores at least its *reference level*
  minus ``slack`` points, and every method at least BC minus ``slack``, on every data set:
  below that, a comparison describes a model that has not learned its data (CLAIMS.md's level
  gate: "BC at its data's mean and the DT at or above BC"). The reference level is the data
  set's mean (``level_reference: data``), or (``mean-action``, :func:`reference_level`) the
  lower of that mean and the mean-action score of the one policy a ``medium`` set was sampled
  from: what a cloner of ``E[a | s]`` can reach where the sampling noise itself lifts the
  returns (hopper's medium policy: 31.5 acting by its mean, 44.5 sampled);
* **targets**: D4RL's published relations hold (the DT at or above BC on hopper-medium and
  well above it on medium-replay), each ``x - y >= min_difference`` on the means;
* **stable**: no pair of methods swaps order by more than ``tolerance`` points against the
  largest rung run, at the same checkpoint.

:func:`choose_rung` names the cheapest (rung, checkpoint) where all three hold, with the
reason; ``None`` with the reasons where none does.

:func:`curve_task` reruns one ladder run with its own config, evaluated more often
(:func:`ladder_curve_run`, ``thesis ladder --curve``): a learning curve, stored apart from the
ladder's runs, that tells a score at a checkpoint from a trend.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib.data.experts import has_medium_run, load_policy_record
from thesis_lib.data.minari_sets import dataset_key, is_minari_id, open_dataset
from thesis_lib.data.recipe import DATASET_SIZES, GENERATOR_VERSION
from thesis_lib.seq import ArchSpec, EvalSpec, TrainSpec, run_offline
from thesis_lib.seq.registry import RTG_METHODS, check_methods
from thesis_lib.sweep import Task, resumed_cpu_s, scratch_file, task_id

__all__ = [
    "CURRENT_LADDER",
    "CURVE_COLUMNS",
    "LADDER_COLUMNS",
    "LEVEL_REFERENCES",
    "Ladder",
    "RUNG_FREE_METHODS",
    "Rung",
    "choose_rung",
    "curve_task",
    "ladder_curve_run",
    "ladder_run",
    "ladder_table",
    "ladder_tasks",
    "load_ladder_file",
    "mean_action_level",
    "parse_rung",
    "reference_level",
    "run_rung",
]

#: The columns of :func:`ladder_table`.
LADDER_COLUMNS = [
    "dataset", "rung", "updates", "method", "seeds", "mean", "ci_low", "ci_high", "scores",
    "data_mean", "bc_reference", "level", "targets", "stable", "passes",
]  # fmt: skip

#: The current ladder file, ``params/<name>.yml``; its runs go to ``studies/<name>/tasks``.
#: ``ladder`` (v1) held BC to its data's mean, which hopper's medium set cannot give a cloner
#: (:func:`mean_action_level`); ``ladder.v2`` reads the same runs with ``mean-action``.
CURRENT_LADDER = "ladder.v2"

#: Methods whose model no rung sizes (BC: an MLP of ``bc_hidden_dim``): one run per data set
#: and seed, keyed and stored at the file's first rung and read at every rung by
#: :func:`ladder_table` (the same run at d64 or d128 would train the same model again).
RUNG_FREE_METHODS = ("BC",)

#: What a ladder's level gate holds BC to (:func:`reference_level`).
LEVEL_REFERENCES = ("data", "mean-action")


@dataclass(frozen=True)
class Rung:
    """One model size of the ladder: ``d_model`` and layers (per level for the HDT)."""

    d_model: int
    n_layers: int

    @property
    def label(self) -> str:
        """``"d32 L1"``."""
        return f"d{self.d_model} L{self.n_layers}"


def parse_rung(text: str) -> Rung:
    """``"d32 L1"`` (or ``"d32L1"``) -> :class:`Rung`.

    Example:
        >>> parse_rung("d64 L2")
        Rung(d_model=64, n_layers=2)
        >>> parse_rung("64/2")
        Traceback (most recent call last):
        ...
        ValueError: Expect a rung as 'd<d_model> L<layers>', e.g. 'd32 L1'; got '64/2'.
    """
    s = str(text).replace(" ", "").lower()
    head, sep, tail = s.partition("l")
    ok = sep and head.startswith("d") and head[1:].isdigit() and tail.isdigit()
    if not ok or int(head[1:]) < 1 or int(tail) < 1:
        raise ValueError(f"Expect a rung as 'd<d_model> L<layers>', e.g. 'd32 L1'; got '{text}'.")
    return Rung(int(head[1:]), int(tail))


@dataclass(frozen=True)
class Ladder:
    """A ladder file (``params/ladder.yml``): what runs, and the rule that reads the runs."""

    datasets: tuple[str, ...]
    methods: tuple[str, ...]
    seeds: tuple[int, ...]
    rungs: tuple[Rung, ...]
    checkpoints: tuple[int, ...]
    dataset_size: str = "full"
    arch: Mapping[str, Any] = field(default_factory=dict)
    """ArchSpec fields every rung shares (``K``, ``dropout``, ...)."""
    train: Mapping[str, Any] = field(default_factory=dict)
    """TrainSpec fields every run shares (``batch_size``, ``lr``, ``warmup_steps``, ...)."""
    episodes: int = 10
    relative_to: str = "BC"
    slack: float = 5.0
    level_reference: str = "data"
    """``data``: BC is held to its data set's mean; ``mean-action``: to
    :func:`reference_level`'s lower bar where the set's policy acts worse by its mean."""
    targets: tuple[Mapping[str, Any], ...] = ()
    tolerance: float = 3.0

    def __post_init__(self) -> None:
        for name in ("datasets", "methods", "seeds", "rungs", "checkpoints"):
            if not getattr(self, name):
                raise ValueError(f"The ladder needs at least one of `{name}`.")
        check_methods(self.methods)
        for d in self.datasets:
            dataset_key(d)  # a clear error for a malformed name
        if self.dataset_size not in DATASET_SIZES:
            raise ValueError(
                f"Unknown dataset_size {self.dataset_size!r}. Valid: {', '.join(DATASET_SIZES)}."
            )
        cps = list(self.checkpoints)
        if cps != sorted(set(cps)) or cps[0] < 1:
            raise ValueError(f"Expect `checkpoints` positive and ascending, got {cps}.")
        if self.level_reference not in LEVEL_REFERENCES:
            raise ValueError(
                f"Unknown level_reference {self.level_reference!r}. "
                f"Valid: {', '.join(LEVEL_REFERENCES)}."
            )
        if self.relative_to not in self.methods:
            raise ValueError(f"relative_to {self.relative_to!r} is not one of the methods.")
        for t in self.targets:
            if set(t) != {"dataset", "x", "y", "min_difference"}:
                raise ValueError(f"A target names dataset, x, y and min_difference, got {dict(t)}.")
            if t["dataset"] not in self.datasets or {t["x"], t["y"]} - set(self.methods):
                raise ValueError(f"Target {dict(t)} names a data set or method not in the ladder.")
        owned = {"d_model", "n_layers"} & set(self.arch) | {
            "seed",
            "iterations",
            "eval_every",
        } & set(self.train)
        if owned:
            raise ValueError(
                f"{sorted(owned)} are the ladder's to set (rungs, seeds, checkpoints); "
                "leave them out of `arch` and `train`."
            )
        ArchSpec(**self.arch)  # unknown fields fail here
        TrainSpec(**self.train)

    @property
    def eval_every(self) -> int:
        """Evaluate where every checkpoint falls: their greatest common divisor."""
        return math.gcd(*self.checkpoints)


def load_ladder_file(path: str | Path) -> Ladder:
    """The :class:`Ladder` of a ladder file (unknown keys are errors)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"No ladder file {p}.")
    data = yaml.safe_load(p.read_text()) or {}
    data.pop("notes", None)
    data.pop("budget_cpu_hours", None)
    valid = set(Ladder.__dataclass_fields__)
    bad = set(data) - valid
    if bad:
        raise ValueError(f"Unknown key(s) {sorted(bad)} in {p}; valid: {sorted(valid)}.")
    for k in ("datasets", "methods", "seeds", "checkpoints", "targets"):
        if k in data:
            if isinstance(data[k], str):
                raise ValueError(f"Expect `{k}` to be a list in {p}, got {data[k]!r}.")
            data[k] = tuple(data[k])
    data["rungs"] = tuple(parse_rung(r) for r in data.get("rungs", ()))
    return Ladder(**data)


# ----------------------------------------------------------------------------------------------
# The runs


def ladder_tasks(ladder: Ladder, rungs: Sequence[Rung] | None = None) -> list[Task]:
    """One task per data set x rung x method x seed (``rungs``: a subset; default all), in the
    order that gives every cell its first seeds early: seed by seed, cheapest rung first.

    A method of :data:`RUNG_FREE_METHODS` has one task per data set and seed, at the file's
    first rung, whichever rungs are asked for (:func:`ladder_table` reads it at each)."""
    chosen = list(ladder.rungs if rungs is None else rungs)
    unknown = [r.label for r in chosen if r not in ladder.rungs]
    if unknown:
        valid = ", ".join(r.label for r in ladder.rungs)
        raise ValueError(f"Unknown rung(s) {unknown}; the ladder's: {valid}.")
    ev = EvalSpec(episodes=ladder.episodes, targets=("max",))
    tasks: dict[str, Task] = {}
    for seed, rung, d, m in itertools.product(
        ladder.seeds, chosen, ladder.datasets, ladder.methods
    ):
        size = ladder.rungs[0] if m in RUNG_FREE_METHODS else rung
        arch = ArchSpec(**{**ladder.arch, "d_model": size.d_model, "n_layers": size.n_layers})
        train = TrainSpec(
            **{**ladder.train, "seed": int(seed)},
            iterations=ladder.checkpoints[-1],
            eval_every=ladder.eval_every,
        )
        config = {
            "method": m,
            "dataset": d,
            "dataset_size": ladder.dataset_size,
            "data_recipe": GENERATOR_VERSION,
            "arch": arch.task_dict(),
            # no device or progress bar in the key: a run is the same task on a CPU or a GPU
            # (ladder_run takes the GPU where there is one, and its rows say which)
            "train": {k: v for k, v in train.task_dict().items() if k not in _NOT_KEYED},
            "eval": asdict(ev),
            "checkpoints": list(ladder.checkpoints),
        }
        task = Task(ladder_run, config)
        tasks.setdefault(task.key, task)
    return list(tasks.values())


#: Updates between a ladder run's checkpoints (kept in its task's scratch folder, so a run cut
#: off resumes from there: :func:`thesis_lib.sweep.task_scratch`).
CHECKPOINT_EVERY = 1000

#: TrainSpec fields a ladder task leaves out of its key.
_NOT_KEYED = ("device", "progress")


def _train(
    config: Mapping[str, Any], iterations: int | None = None, eval_every: int | None = None
) -> tuple[dict[int, dict[str, Any]], float, float | None, str]:
    """Train a ladder run's ``config`` (``iterations`` and ``eval_every`` in place of its own
    where given) and evaluate it: the evaluations by update (at the data set's best return for
    RTG methods), the CPU seconds, the data set's mean normalised score and the device."""
    import torch  # lazy: a worker process sets its threads before the first model

    torch.set_num_threads(1)
    device = "cuda" if torch.cuda.is_available() else "cpu"
    if config.get("data_recipe", GENERATOR_VERSION) != GENERATOR_VERSION:
        raise ValueError(
            f"This run's data is of recipe {config['data_recipe']}, this checkout makes "
            f"{GENERATOR_VERSION}: its rows stay a record and cannot be redone."
        )
    ds = open_dataset(config["dataset"], config["dataset_size"])
    ev = dict(config["eval"])
    ev["targets"] = tuple(ev["targets"])
    arch = ArchSpec.from_task(config["arch"])
    train = {**config["train"], "device": device}
    if iterations is not None:
        train["iterations"] = iterations
    if eval_every is not None:
        train["eval_every"] = eval_every
    # a run cut off (the session's end) resumes from its last checkpoint (CHECKPOINT_EVERY),
    # kept in the task's scratch folder until its rows are stored
    checkpoint = scratch_file("train.pt")
    t0 = time.process_time()
    rows = run_offline(
        config["method"],
        ds,
        arch,
        TrainSpec.from_task(train),
        EvalSpec(**ev),
        task=dataset_key(config["dataset"])[0],
        checkpoint=checkpoint,
        checkpoint_every=CHECKPOINT_EVERY,
    )
    train_s = round(time.process_time() - t0 + resumed_cpu_s(), 1)  # with its cut-off parts
    scores = ds.normalized_scores()
    data_mean = None if scores is None or not len(scores) else float(np.mean(scores))
    want = "max" if config["method"] in RTG_METHODS else "none"
    by_iteration = {int(r["iteration"]): r for r in rows if r["target"] == want}
    return by_iteration, train_s, data_mean, device


def run_rung(config: Mapping[str, Any]) -> str:
    """The rung a ladder run's rows carry: its model's size. A rung-free method's run
    (:data:`RUNG_FREE_METHODS`) carries the first rung at whichever rung it was asked for."""
    arch = ArchSpec.from_task(config["arch"])
    return Rung(arch.d_model, arch.n_layers).label


def _row(config: Mapping[str, Any], updates: int, ev: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "dataset": config["dataset"],
        "rung": run_rung(config),
        "updates": updates,
        "method": config["method"],
        "seed": int(config["train"]["seed"]),
        "score": float(ev["score_mean"]),
        "return_mean": float(ev["return_mean"]),
        "length_mean": float(ev["length_mean"]),
    }


@task_id("thesis_lib.ladder:ladder_run")
def ladder_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """One ladder run (a sweep task): train to the last checkpoint, one row per checkpoint
    (the evaluation at that many updates, at the data set's best return for RTG methods).
    It trains on the GPU where there is one (``device`` in its rows), else on one CPU core."""
    by_iteration, train_s, data_mean, device = _train(config)
    missing = [c for c in config["checkpoints"] if c not in by_iteration]
    if missing:
        raise RuntimeError(
            f"No evaluation at checkpoint(s) {missing} (got {sorted(by_iteration)})."
        )
    return [
        _row(config, c, by_iteration[c])
        | {"data_mean": data_mean, "train_s": train_s, "device": device}
        for c in config["checkpoints"]
    ]


#: The columns of :func:`ladder_curve_run`'s rows.
CURVE_COLUMNS = [
    "dataset", "rung", "updates", "method", "seed", "score", "return_mean", "length_mean",
    "loss", "train_s", "device",
]  # fmt: skip


def curve_task(
    ladder: Ladder, dataset: str, rung: str, method: str, seed: int, every: int, iterations: int
) -> Task:
    """A learning curve of one ladder run: the run's own config (data, model, training,
    evaluation), trained to ``iterations`` updates and evaluated every ``every`` (a
    :func:`ladder_curve_run` task). It shows whether a score at a checkpoint is a point or a
    trend: the ladder evaluates only at its checkpoints, 10 episodes each.

    Raises:
        ValueError: no such run in the ladder, or not ``1 <= every <= iterations``.
    """
    if every < 1 or iterations < every:
        raise ValueError(
            f"Expect 1 <= every <= iterations, got every={every}, iterations={iterations}."
        )
    size = parse_rung(rung)
    found = [
        t
        for t in ladder_tasks(ladder, [size])
        if t.config["dataset"] == dataset
        and t.config["method"] == method
        and t.config["train"]["seed"] == seed
    ]
    if not found:
        raise ValueError(
            f"No ladder run {method} on {dataset} at {size.label}, seed {seed}; the ladder's: "
            f"data sets {list(ladder.datasets)}, methods {list(ladder.methods)}, "
            f"seeds {list(ladder.seeds)}."
        )
    config = {**found[0].config, "curve": {"every": int(every), "iterations": int(iterations)}}
    return Task(ladder_curve_run, config)


@task_id("thesis_lib.ladder:ladder_curve_run")
def ladder_curve_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """A learning curve (a sweep task, :func:`curve_task`): one row per evaluation, with the
    training loss of the last update before it."""
    curve = config["curve"]
    by_iteration, train_s, _, device = _train(config, curve["iterations"], curve["every"])
    return [
        _row(config, it, ev) | {"loss": float(ev["loss"]), "train_s": train_s, "device": device}
        for it, ev in sorted(by_iteration.items())
    ]


# ----------------------------------------------------------------------------------------------
# The table and the choice


def mean_action_level(dataset: str) -> float | None:
    """The D4RL-normalised score of the policy a ``medium`` set was sampled from, acting by its
    mean action (the shipped medium run's ``medium_normalized``, 100 episodes), where the set
    was sampled from one such policy (its record has a sampled score); else ``None``
    (Minari sets, other tiers, mixtures such as medium-replay).

    A behaviour cloner fits ``E[a | s]``: where the sampling noise *lifts* a policy's returns,
    as it does for hopper's SAC medium snapshot (31.5 by its mean action, 44.5 sampled: the
    noise carries some episodes past the fall its mean action makes at about 345 steps), BC
    reaches the mean action's score, not the data's mean.

    >>> round(mean_action_level("hopper/medium"), 1), mean_action_level("hopper/medium-replay")
    (31.5, None)
    """
    if is_minari_id(dataset):
        return None
    task, tier = dataset_key(dataset)
    if tier != "medium" or not has_medium_run(task):
        return None
    rec = load_policy_record(task, role="medium")
    if rec.medium_sampled_normalized is None or rec.medium_normalized is None:
        return None
    return float(rec.medium_normalized)


def reference_level(ladder: Ladder, dataset: str, data_mean: float | None) -> float | None:
    """The score the level gate holds the ladder's ``relative_to`` method (BC) to, before its
    slack: the data set's mean, or with ``level_reference: mean-action`` the lower of that mean
    and :func:`mean_action_level` (where the set's policy does better by its mean, as D4RL's
    medium policies and ours for walker2d and halfcheetah do, the data's mean stays the bar)."""
    if data_mean is None:
        return None
    if ladder.level_reference == "mean-action":
        level = mean_action_level(dataset)
        if level is not None:
            return min(float(data_mean), level)
    return float(data_mean)


def _interval(x: np.ndarray) -> tuple[float, float]:
    """The 95% t interval of the mean of ``x`` (NaN for fewer than 2 values)."""
    from scipy import stats

    if len(x) < 2:
        return math.nan, math.nan
    half = float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x)))
    return float(x.mean()) - half, float(x.mean()) + half


def _swapped(a: Mapping[str, float], b: Mapping[str, float], tolerance: float) -> list[str]:
    """The pairs of methods ordered one way by more than ``tolerance`` in ``a`` and the other
    way by more than ``tolerance`` in ``b``.

    Example:
        >>> _swapped({"BC": 30, "DT": 40}, {"BC": 41, "DT": 36}, 3.0)
        ['DT > BC became DT < BC']
        >>> _swapped({"BC": 30, "DT": 40}, {"BC": 38, "DT": 36}, 3.0)
        []
    """
    out = []
    for x, y in itertools.combinations(sorted(set(a) & set(b)), 2):
        da, db = a[x] - a[y], b[x] - b[y]
        if abs(da) > tolerance and abs(db) > tolerance and (da > 0) != (db > 0):
            first, second = (y, x) if da > 0 else (x, y)  # the larger first
            out.append(f"{second} > {first} became {second} < {first}")
    return out


def ladder_table(ladder: Ladder, rows: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """One row per data set x rung x checkpoint x method with runs (:data:`LADDER_COLUMNS`).

    ``level``, ``targets``, ``stable`` and ``passes`` are the rung's verdicts at that
    checkpoint (the same on each of its rows): ``True``, ``False``, or ``None`` where a method
    or a seed is missing (``stable``: also at the largest rung itself, or without it). The runs
    of :data:`RUNG_FREE_METHODS` (stored at the first rung) stand at every rung that has runs.
    """
    df = pd.DataFrame(list(rows))
    if df.empty:
        return pd.DataFrame(columns=LADDER_COLUMNS)
    free = df["method"].isin(RUNG_FREE_METHODS)
    df = pd.concat(
        [df[~free]] + [df[free].assign(rung=lab) for lab in df["rung"].drop_duplicates()],
        ignore_index=True,
    ).drop_duplicates(["dataset", "rung", "updates", "method", "seed"])
    cells = []
    for (d, rung, n, m), g in df.groupby(["dataset", "rung", "updates", "method"], sort=False):
        x = g.sort_values("seed")["score"].to_numpy(dtype=float)
        lo, hi = _interval(x)
        cells.append(
            {
                "dataset": d,
                "rung": rung,
                "updates": int(n),
                "method": m,
                "seeds": len(x),
                "mean": float(x.mean()),
                "ci_low": lo,
                "ci_high": hi,
                "scores": " ".join(f"{v:.1f}" for v in x),
                "data_mean": g["data_mean"].dropna().mean()
                if g["data_mean"].notna().any()
                else None,
            }
        )
    table = pd.DataFrame(cells)
    means: dict[tuple[Any, ...], dict[str, float]] = {
        (r.dataset, r.rung, r.updates): {} for r in table.itertuples()
    }
    complete = set()
    for r in table.itertuples():
        means[(r.dataset, r.rung, r.updates)][r.method] = r.mean
        if r.seeds == len(ladder.seeds):
            complete.add((r.dataset, r.rung, r.updates, r.method))
    known = table.dropna(subset=["data_mean"])
    data_means = {d: float(g["data_mean"].mean()) for d, g in known.groupby("dataset")}
    bars = {d: reference_level(ladder, d, data_means.get(d)) for d in set(table["dataset"])}
    table["bc_reference"] = table["dataset"].map(bars)
    labels = [r.label for r in ladder.rungs]
    ran = [lab for lab in labels if lab in set(table["rung"])]
    top = ran[-1] if ran else None
    verdicts: dict[tuple[Any, Any], tuple[bool | None, ...]] = {}

    def complete_at(rung: Any, n: Any) -> bool:
        """Every data set x method of the ladder has all its seeds at (rung, n)."""
        return all((d, rung, n, m) in complete for d in ladder.datasets for m in ladder.methods)

    for rung, n in {(r.rung, r.updates) for r in table.itertuples()}:
        if not complete_at(rung, n):
            verdicts[(rung, n)] = (None, None, None, None)
            continue
        bc_at_data = all(
            (bar := bars.get(d)) is not None
            and means[(d, rung, n)][ladder.relative_to] >= bar - ladder.slack
            for d in ladder.datasets
        )
        level = bc_at_data and all(
            means[(d, rung, n)][m] >= means[(d, rung, n)][ladder.relative_to] - ladder.slack
            for d in ladder.datasets
            for m in ladder.methods
        )
        targets = all(
            means[(t["dataset"], rung, n)][t["x"]] - means[(t["dataset"], rung, n)][t["y"]]
            >= t["min_difference"]
            for t in ladder.targets
        )
        stable: bool | None = None
        if top is not None and rung != top and complete_at(top, n):
            stable = not any(
                _swapped(means[(d, rung, n)], means[(d, top, n)], ladder.tolerance)
                for d in ladder.datasets
            )
        passes = None if stable is None else bool(level and targets and stable)
        verdicts[(rung, n)] = (level, targets, stable, passes)
    for i, key in enumerate(("level", "targets", "stable", "passes")):
        table[key] = [verdicts[(r.rung, r.updates)][i] for r in table.itertuples()]
    order = {lab: i for i, lab in enumerate(labels)}
    table["_r"] = table["rung"].map(order)
    table["_d"] = table["dataset"].map({d: i for i, d in enumerate(ladder.datasets)})
    table["_m"] = table["method"].map({m: i for i, m in enumerate(ladder.methods)})
    table = table.sort_values(["_r", "updates", "_d", "_m"]).drop(columns=["_r", "_d", "_m"])
    return table[LADDER_COLUMNS].reset_index(drop=True)


def _verdict(x: Any) -> bool | None:
    """A verdict cell as ``True``, ``False`` or ``None`` (whatever dtype the column took)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return None
    return bool(x)


def choose_rung(ladder: Ladder, table: pd.DataFrame) -> tuple[tuple[str, int] | None, str]:
    """The cheapest (rung, updates) whose verdicts all pass (rungs in the file's order, fewer
    updates first), and why; ``(None, why)`` where none does yet."""
    if table.empty:
        return None, "no runs yet"
    why = []
    for rung in ladder.rungs:
        for n in ladder.checkpoints:
            cell = table[(table["rung"] == rung.label) & (table["updates"] == n)]
            if cell.empty:
                why.append(f"{rung.label} @ {n:,}: not run")
                continue
            v = {k: _verdict(cell.iloc[0][k]) for k in ("level", "targets", "stable", "passes")}
            if v["passes"]:
                return (rung.label, n), (
                    f"{rung.label} @ {n:,} updates: {ladder.relative_to} within "
                    f"{ladder.slack:g} of its reference level ({ladder.level_reference}) and "
                    f"every method within "
                    f"{ladder.slack:g} of it, the targets hold, and no pair of methods swaps "
                    f"by more than {ladder.tolerance:g} points against the largest rung"
                )
            failed = [k for k in ("level", "targets", "stable") if v[k] is False]
            unknown = [k for k in ("level", "targets", "stable") if v[k] is None]
            why.append(
                f"{rung.label} @ {n:,}: "
                + (f"fails {', '.join(failed)}" if failed else "")
                + ("; " if failed and unknown else "")
                + (f"{', '.join(unknown)} not known yet" if unknown else "")
            )
    return None, "; ".join(why)
