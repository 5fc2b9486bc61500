"""The scale ladder (issue #36): its file, its tasks, the table's verdicts and the chosen size,
and one tiny ladder run end to end through ``thesis ladder``."""

from __future__ import annotations

import dataclasses
import json
import math

import pandas as pd
import pytest

from thesis_lib.ladder import (
    CURRENT_LADDER,
    LADDER_COLUMNS,
    Ladder,
    Rung,
    choose_rung,
    ladder_table,
    ladder_tasks,
    load_ladder_file,
    mean_action_level,
    parse_rung,
    reference_level,
)
from thesis_lib.paths import project_root
from thesis_lib.seq import ArchSpec


def test_the_committed_ladder_file_gives_one_task_per_cell_and_seed():
    ladder = load_ladder_file(project_root() / "params" / "ladder.yml")
    assert ladder.rungs == (Rung(32, 1), Rung(64, 2), Rung(128, 3))
    assert ladder.checkpoints == (10_000, 30_000) and ladder.eval_every == 10_000
    tasks = ladder_tasks(ladder)
    # BC (rung-free) once per data set and seed, the three others at every rung
    assert len(tasks) == 2 * 3 * (1 + 3 * 3) and len({t.key for t in tasks}) == len(tasks)
    first = tasks[0].config
    assert first["train"]["iterations"] == 30_000 and first["train"]["eval_every"] == 10_000
    assert first["dataset_size"] == "full" and first["arch"]["init"] == "normal"
    assert "device" not in first["train"]  # the same task on a CPU or a GPU
    # seed by seed: every cell's first seed comes before any second seed
    seeds = [t.config["train"]["seed"] for t in tasks]
    assert seeds == sorted(seeds)
    small = ladder_tasks(ladder, [parse_rung("d32 L1")])
    assert len(small) == 24 and {t.key for t in small} <= {t.key for t in tasks}
    # a larger rung alone still asks for BC's runs, at the first rung, where they are stored
    d64 = ladder_tasks(ladder, [parse_rung("d64 L2")])
    bc = [t for t in d64 if t.config["method"] == "BC"]
    assert len(d64) == 24 and {t.key for t in bc} <= {t.key for t in small}
    assert {t.config["arch"]["d_model"] for t in d64 if t.config["method"] != "BC"} == {64}
    with pytest.raises(ValueError, match=r"Unknown rung\(s\) \['d16 L1'\]"):
        ladder_tasks(ladder, [Rung(16, 1)])


def test_the_second_ladder_file_reads_the_first_files_runs_with_its_own_level_gate():
    """``ladder.v2`` changes only the level gate: the same tasks, so the first file's runs are
    its runs (copied into its store), and nothing else of the design moved."""
    root = project_root()
    v1 = load_ladder_file(root / "params" / "ladder.yml")
    v2 = load_ladder_file(root / "params" / f"{CURRENT_LADDER}.yml")
    assert (v1.level_reference, v2.level_reference) == ("data", "mean-action")
    assert dataclasses.replace(v2, level_reference="data") == v1
    assert [t.key for t in ladder_tasks(v1)] == [t.key for t in ladder_tasks(v2)]
    first = {f.name for f in (root / "studies" / "ladder" / "tasks").glob("*.json")}
    assert first and first <= {
        f.name for f in (root / "studies" / CURRENT_LADDER / "tasks").glob("*.json")
    }


def test_the_mean_action_reference_is_the_lower_of_the_datas_mean_and_its_policys_mean_action():
    # hopper's medium snapshot falls at about 345 steps by its mean action (31.5), its sampled
    # episodes score 44.5; walker2d's does better by its mean (68.8 against 64.8 sampled)
    hopper = mean_action_level("hopper/medium")
    assert hopper is not None and 30.0 < hopper < 33.0
    walker = mean_action_level("walker2d/medium")
    assert walker is not None and walker > 65.0
    for name in ("hopper/medium-replay", "hopper/expert", "D4RL/door/human-v2"):
        assert mean_action_level(name) is None  # a mixture, another tier, a Minari set
    v2 = dataclasses.replace(LADDER, level_reference="mean-action")
    assert reference_level(v2, "hopper/medium", 43.8) == pytest.approx(hopper)
    assert reference_level(v2, "hopper/medium", 20.0) == 20.0  # the data's mean where lower
    assert reference_level(v2, "walker2d/medium", 64.8) == 64.8
    assert reference_level(v2, "hopper/medium-replay", 13.6) == 13.6
    assert reference_level(LADDER, "hopper/medium", 43.8) == 43.8
    assert reference_level(v2, "hopper/medium", None) is None


def _write(tmp_path, text):
    f = tmp_path / "ladder.yml"
    f.write_text(text)
    return f


BASE = """datasets: [hopper/medium]
methods: [BC, DT]
seeds: [0]
rungs: ["d8 L1"]
checkpoints: [4, 8]
"""


@pytest.mark.parametrize(
    "extra, message",
    [
        ("colour: red\n", r"Unknown key\(s\) \['colour'\]"),
        ("arch: {d_model: 64}\n", r"\['d_model'\] are the ladder's to set"),
        ("train: {iterations: 5}\n", r"\['iterations'\] are the ladder's to set"),
        ("relative_to: HDT\n", "relative_to 'HDT' is not one of the methods"),
        (
            "targets: [{dataset: hopper/medium, x: DT, y: HDT, min_difference: 0}]\n",
            "names a data set or method not in the ladder",
        ),
        ("dataset_size: huge\n", "Unknown dataset_size 'huge'"),
        ("level_reference: policy\n", "Unknown level_reference 'policy'. Valid: data, mean-action"),
    ],
)
def test_a_bad_ladder_file_says_what_is_wrong(tmp_path, extra, message):
    with pytest.raises(ValueError, match=message):
        load_ladder_file(_write(tmp_path, BASE + extra))


def test_bad_rungs_checkpoints_and_methods_are_named(tmp_path):
    with pytest.raises(ValueError, match="ascending"):
        load_ladder_file(_write(tmp_path, BASE.replace("[4, 8]", "[8, 4]")))
    with pytest.raises(ValueError, match="Expect a rung as"):
        load_ladder_file(_write(tmp_path, BASE.replace('"d8 L1"', '"8/1"')))
    with pytest.raises(ValueError, match="Unknown method 'DTT'"):
        load_ladder_file(_write(tmp_path, BASE.replace("[BC, DT]", "[BC, DTT]")))
    with pytest.raises(ValueError, match="to be a list"):
        load_ladder_file(_write(tmp_path, BASE.replace("seeds: [0]", "seeds: '0'")))
    with pytest.raises(FileNotFoundError):
        load_ladder_file(tmp_path / "none.yml")


# ----------------------------------------------------------------------------------------------
# The verdicts, on made-up rows

LADDER = Ladder(
    datasets=("hopper/medium", "hopper/medium-replay"),
    methods=("BC", "DT", "HDT"),
    seeds=(0, 1, 2),
    rungs=(Rung(32, 1), Rung(64, 2), Rung(128, 3)),
    checkpoints=(10, 30),
    dataset_size="smoke",
    targets=(
        {"dataset": "hopper/medium", "x": "DT", "y": "BC", "min_difference": 0.0},
        {"dataset": "hopper/medium-replay", "x": "DT", "y": "BC", "min_difference": 10.0},
    ),
)


DATA_MEANS = {"hopper/medium": 40.0, "hopper/medium-replay": 18.0}


def _rows(means, data_means=DATA_MEANS):
    """Rows of three seeds at ``mean - 1, mean, mean + 1`` for ``{(dataset, rung, updates,
    method): mean}``."""
    return [
        {
            "dataset": d,
            "rung": r,
            "updates": n,
            "method": m,
            "seed": s,
            "score": mean + s - 1,
            "data_mean": data_means[d],
        }
        for (d, r, n, m), mean in means.items()
        for s in range(3)
    ]


def _means(rung, n, m_scores, mr_scores):
    return {
        **{("hopper/medium", rung, n, k): v for k, v in zip(("BC", "DT", "HDT"), m_scores)},
        **{("hopper/medium-replay", rung, n, k): v for k, v in zip(("BC", "DT", "HDT"), mr_scores)},
    }


def test_the_table_reads_levels_targets_and_stability_and_the_cheapest_passing_size_wins():
    means = {}
    for n in (10, 30):
        # d32: the HDT below BC by 10 on medium (level fails)
        means |= _means("d32 L1", n, (40, 42, 30), (20, 35, 30))
        # d64 at 10 updates: DT only 5 above BC on medium-replay (targets fail); at 30: all pass
        means |= _means("d64 L2", n, (40, 44, 41), (20, 25 if n == 10 else 36, 31))
        means |= _means("d128 L3", n, (41, 45, 43), (21, 38, 32))
    table = ladder_table(LADDER, _rows(means))
    assert list(table.columns) == LADDER_COLUMNS and len(table) == 3 * 2 * 2 * 3
    cell = table[(table["rung"] == "d32 L1") & (table["updates"] == 10) & (table["method"] == "HDT")
                 & (table["dataset"] == "hopper/medium")].iloc[0]  # fmt: skip
    assert cell["mean"] == 30 and cell["seeds"] == 3 and cell["scores"] == "29.0 30.0 31.0"
    assert math.isclose(cell["ci_high"] - cell["mean"], 4.303 / math.sqrt(3), rel_tol=1e-3)
    v = table.drop_duplicates(["rung", "updates"]).set_index(["rung", "updates"])
    assert not v.loc[("d32 L1", 10), "level"] and v.loc[("d32 L1", 10), "passes"] is False
    assert v.loc[("d64 L2", 10), "level"] and not v.loc[("d64 L2", 10), "targets"]
    assert v.loc[("d64 L2", 30), "passes"] is True
    assert v.loc[("d128 L3", 30), "stable"] is None  # the largest rung has nothing to compare to
    chosen, why = choose_rung(LADDER, table)
    assert chosen == ("d64 L2", 30) and "BC within 5 of its reference level (data)" in why
    assert (table["bc_reference"] == table["dataset"].map(DATA_MEANS)).all()
    # BC 11 points below its data (medium at 51): no rung passes the level gate
    low = ladder_table(LADDER, _rows(means, {**DATA_MEANS, "hopper/medium": 51.0}))
    assert not low["level"].any() and choose_rung(LADDER, low)[0] is None
    # ... unless the set's policy scores less by its mean action (hopper's: 31.5): BC at 40 has
    # reached what a cloner can, and the same rows pass where they passed before
    v2 = dataclasses.replace(LADDER, level_reference="mean-action")
    low = ladder_table(v2, _rows(means, {**DATA_MEANS, "hopper/medium": 51.0}))
    assert choose_rung(v2, low)[0] == ("d64 L2", 30)
    ref = low.drop_duplicates("dataset").set_index("dataset")["bc_reference"]
    assert ref["hopper/medium"] == pytest.approx(mean_action_level("hopper/medium"))
    assert ref["hopper/medium-replay"] == 18.0


def test_a_swap_against_the_largest_rung_fails_stability_and_missing_seeds_decide_nothing():
    means = _means("d32 L1", 30, (40, 50, 42), (20, 40, 30)) | _means(
        "d128 L3", 30, (40, 44, 52), (20, 40, 30)
    )  # d32: DT 8 above the HDT on medium; d128: the HDT 8 above the DT
    table = ladder_table(LADDER, _rows(means))
    v = table.drop_duplicates(["rung", "updates"]).set_index(["rung", "updates"])
    assert v.loc[("d32 L1", 30), "level"] and v.loc[("d32 L1", 30), "stable"] is False
    chosen, why = choose_rung(LADDER, table)
    assert chosen is None and "d32 L1 @ 30: fails stable" in why and "d64 L2 @ 10: not run" in why
    rows = [r for r in _rows(means) if not (r["rung"] == "d32 L1" and r["seed"] == 2)]
    v = (
        ladder_table(LADDER, rows)
        .drop_duplicates(["rung", "updates"])
        .set_index(["rung", "updates"])
    )
    assert v.loc[("d32 L1", 30), "level"] is None and v.loc[("d32 L1", 30), "passes"] is None
    assert choose_rung(LADDER, pd.DataFrame()) == (None, "no runs yet")


def test_bc_runs_once_at_the_first_rung_and_stands_at_every_rung():
    """BC's model is an MLP no rung sizes, so its runs at d32 are its runs at d128: the same
    parameters, and the table reads them at each rung with runs."""
    import types

    import torch

    from thesis_lib.seq.registry import build_model

    seq = types.SimpleNamespace(states=torch.zeros(2, 11), actions=torch.zeros(2, 3))
    shapes = [
        {k: tuple(v.shape) for k, v in build_model("BC", seq, ArchSpec(d_model=d, n_layers=n))
         .state_dict().items()}
        for d, n in ((32, 1), (128, 3))
    ]  # fmt: skip
    assert shapes[0] == shapes[1]
    dt = [sum(p.numel() for p in build_model("DT", seq, ArchSpec(d_model=d, n_layers=n))
              .parameters()) for d, n in ((32, 1), (128, 3))]  # fmt: skip
    assert dt[0] < dt[1]  # a rung does size the others
    means = _means("d32 L1", 30, (40, 42, 41), (20, 35, 30)) | _means(
        "d64 L2", 30, (40, 44, 41), (20, 36, 31)
    )
    rows = [r for r in _rows(means) if not (r["method"] == "BC" and r["rung"] == "d64 L2")]
    table = ladder_table(LADDER, rows)
    bc = table[table["method"] == "BC"]
    assert list(bc["rung"]) == ["d32 L1", "d32 L1", "d64 L2", "d64 L2"]
    assert (bc["seeds"] == 3).all() and set(bc["mean"]) == {40.0, 20.0}
    v = table.drop_duplicates(["rung", "updates"]).set_index(["rung", "updates"])
    assert v.loc[("d64 L2", 30), "level"] and v.loc[("d64 L2", 30), "targets"]
    # with BC at d32 only, the table has no d64 rows for it to stand at
    only_bc = [r for r in rows if r["method"] == "BC"]
    assert set(ladder_table(LADDER, only_bc)["rung"]) == {"d32 L1"}


# ----------------------------------------------------------------------------------------------
# One tiny ladder end to end


def test_a_tiny_ladder_runs_through_the_cli_and_writes_its_table(tmp_path, capsys):
    from thesis_lib.cli import main

    f = _write(tmp_path, BASE + "dataset_size: smoke\nepisodes: 1\ntrain: {warmup_steps: 2}\n")
    store = tmp_path / "ladder" / "tasks"
    assert main(["ladder", "-f", str(f), "--store", str(store)]) == 0
    out = capsys.readouterr().out
    assert "none yet" in out and "written:" in out
    table = pd.read_csv(tmp_path / "ladder" / "ladder.csv")
    assert set(table["updates"]) == {4, 8} and set(table["method"]) == {"BC", "DT"}
    assert (table["rung"] == "d8 L1").all() and table["mean"].notna().all()
    assert table["data_mean"].between(20, 60).all()  # hopper medium's normalised mean
    stored = sorted(store.glob("*.json"))
    assert len(stored) == 2
    assert json.loads(stored[0].read_text())["rows"][0]["device"] in ("cpu", "cuda")
    assert main(["ladder", "-f", str(f), "--store", str(store), "--rungs", "d9 L1"]) == 1
    assert "Unknown rung" in capsys.readouterr().err


def test_a_ladder_run_cut_off_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    """A run cut off after a checkpoint resumes from it when the ladder runs again (its
    rows those of an uninterrupted run; its CPU seconds both parts'), and the checkpoint goes
    once the run is stored."""
    import thesis_lib.ladder as ladder_mod
    from thesis_lib.seq.trainer import Trainer
    from thesis_lib.sweep import GridFailed, TaskStore, run_tasks, scratch_of

    f = _write(tmp_path, BASE + "dataset_size: smoke\nepisodes: 1\ntrain: {warmup_steps: 2}\n")
    dt = [t for t in ladder_tasks(load_ladder_file(f)) if t.config["method"] == "DT"]
    straight = run_tasks(dt, progress=False)  # no store: no checkpoint
    monkeypatch.setattr(ladder_mod, "CHECKPOINT_EVERY", 2)
    step, store = Trainer.step, tmp_path / "tasks"

    def cut_off(self):
        if self.iteration == 6:
            raise RuntimeError("cut off")
        return step(self)

    monkeypatch.setattr(Trainer, "step", cut_off)
    with pytest.raises((GridFailed, RuntimeError)):
        run_tasks(dt, store=store, progress=False, executor="inprocess")
    ckpt = scratch_of(store, dt[0].key) / "train.pt"
    import torch

    before = torch.load(ckpt, weights_only=True)
    assert before["iteration"] == 6
    monkeypatch.setattr(Trainer, "step", step)
    resumed = run_tasks(dt, store=store, progress=False, executor="inprocess")
    cols = ["updates", "score", "return_mean", "length_mean"]
    pd.testing.assert_frame_equal(resumed[cols], straight[cols])
    assert not ckpt.parent.exists()
    assert resumed["train_s"].iloc[0] >= round(before["cpu_s"], 1) > 0  # both parts
    record = TaskStore(store).read(dt[0].key)
    assert record["resumed_cpu_s"] == pytest.approx(before["cpu_s"], abs=1e-3)
    assert record["cpu_s"] >= record["resumed_cpu_s"]


def test_a_learning_curve_reruns_a_ladder_run_with_denser_evaluations(tmp_path, capsys):
    """``--curve``: the ladder run's own config, trained further and evaluated more often; the
    same evaluation at a checkpoint as the ladder run (deterministic training), stored apart."""
    from thesis_lib.cli import main
    from thesis_lib.ladder import CURVE_COLUMNS, curve_task, ladder_curve_run, ladder_run

    text = BASE + "dataset_size: smoke\nepisodes: 1\ntrain: {warmup_steps: 2}\n"
    f = _write(tmp_path, text)
    store = tmp_path / "ladder" / "tasks"
    args = ["ladder", "-f", str(f), "--store", str(store)]
    assert (
        main([*args, "--curve", "hopper/medium", "d8 L1", "DT", "0", "--every", "2", "--to", "10"])
        == 0
    )
    out = capsys.readouterr().out
    assert "DT on hopper/medium at d8 L1" in out and "written:" in out
    curves = pd.read_csv(tmp_path / "ladder" / "curves.csv")
    assert list(curves.columns) == CURVE_COLUMNS
    assert list(curves["updates"]) == [2, 4, 6, 8, 10] and curves["loss"].notna().all()
    assert not list(store.glob("*.json"))  # the ladder's own runs are not touched
    assert len(list((tmp_path / "ladder" / "curves").glob("*.json"))) == 1
    # the ladder run itself gives the same score at its checkpoints
    ladder = load_ladder_file(f)
    run = next(t for t in ladder_tasks(ladder) if t.config["method"] == "DT")
    at = {r["updates"]: r["score"] for r in ladder_run(dict(run.config))}
    curve_at = {u: s for u, s in zip(curves["updates"], curves["score"]) if u in at}
    assert at == pytest.approx(curve_at, abs=1e-3) and len(at) == 2  # curves.csv: 3 decimals
    task = curve_task(ladder, "hopper/medium", "d8 L1", "DT", 0, 2, 10)
    assert task.config["curve"] == {"every": 2, "iterations": 10}
    assert task.fn is ladder_curve_run and task.key != run.key
    with pytest.raises(ValueError, match="No ladder run HDT on hopper/medium at d8 L1, seed 0"):
        curve_task(ladder, "hopper/medium", "d8 L1", "HDT", 0, 2, 10)
    with pytest.raises(ValueError, match="every <= iterations"):
        curve_task(ladder, "hopper/medium", "d8 L1", "DT", 0, 20, 10)
    with pytest.raises(SystemExit, match="SEEDS as integers"):
        main([*args, "--curve", "hopper/medium", "d8 L1", "DT", "zero"])
    with pytest.raises(SystemExit, match="use them with --curve"):
        main([*args, "--every", "2"])


def test_a_rung_free_methods_curve_at_a_later_rung_prints_its_run(tmp_path, capsys):
    """BC runs once, at the first rung: its curve asked for at a later rung is that run, and
    the printed table holds it (it was empty when the rows were filtered by the asked rung)."""
    from thesis_lib.cli import main
    from thesis_lib.ladder import curve_task, run_rung

    text = BASE.replace('["d8 L1"]', '["d8 L1", "d16 L2"]') + (
        "dataset_size: smoke\nepisodes: 1\ntrain: {warmup_steps: 2}\n"
    )
    f = _write(tmp_path, text)
    ladder = load_ladder_file(f)
    bc = curve_task(ladder, "hopper/medium", "d16 L2", "BC", 0, 2, 4)
    assert bc.key == curve_task(ladder, "hopper/medium", "d8 L1", "BC", 0, 2, 4).key
    assert run_rung(bc.config) == "d8 L1"
    assert run_rung(curve_task(ladder, "hopper/medium", "d16 L2", "DT", 0, 2, 4).config) == (
        "d16 L2"
    )
    args = ["ladder", "-f", str(f), "--store", str(tmp_path / "ladder" / "tasks")]
    assert (
        main([*args, "--curve", "hopper/medium", "d16 L2", "BC", "0", "--every", "2", "--to", "4"])
        == 0
    )
    out = capsys.readouterr().out
    assert "BC on hopper/medium at d8 L1 (rung-free: the same run at d16 L2)" in out
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("BC on"))
    rows = [line.split() for line in lines[head + 1 :] if line.split()[:1] in (["2"], ["4"])]
    assert [r[0] for r in rows] == ["2", "4"] and all(len(r) == 2 for r in rows)


def test_a_ladder_file_keeps_its_runs_under_its_own_name(tmp_path, monkeypatch, capsys):
    """Without ``--store``, ``params/<name>.yml`` reads and writes ``studies/<name>/``."""
    from thesis_lib.cli import main

    (tmp_path / "_toc.yml").write_text("root: intro\n")
    (tmp_path / "params").mkdir()
    f = tmp_path / "params" / "mine.yml"
    f.write_text(BASE)
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    assert main(["ladder", "-f", str(f), "--table"]) == 0
    assert "no ladder runs stored" in capsys.readouterr().out
    assert (tmp_path / "studies" / "mine" / "ladder.csv").is_file()


def test_the_claims_page_shows_the_ladder_its_verdicts_and_its_choice():
    from thesis_lib.chapters.claims import ladder_choice, ladder_view, load_ladder

    committed = load_ladder()
    view = ladder_view(committed)
    assert len(view) == committed.groupby(["rung", "updates", "dataset"]).ngroups > 0
    assert list(view.columns[:7]) == ["rung", "updates", "data set", "BC", "DT", "HDT", "DM-noRTG"]
    # made-up rows of the current file: at d32 the level and the targets hold on both sets
    # (hopper medium's BC at 32 is held to its mean-action 31.5, not the data's 43.8), and a
    # d64 rung in the same order makes d32 stable: the cheapest passing size
    v2 = load_ladder_file(project_root() / "params" / f"{CURRENT_LADDER}.yml")
    score = {"hopper/medium": (32, 35, 34, 36), "hopper/medium-replay": (12, 40, 30, 35)}
    data = {"hopper/medium": 43.8, "hopper/medium-replay": 13.6}
    rows = [
        {"dataset": d, "rung": r, "updates": n, "method": m, "seed": s,
         "score": score[d][v2.methods.index(m)] + s - 1, "data_mean": data[d]}
        for d in v2.datasets for r in ("d32 L1", "d64 L2") for n in v2.checkpoints
        for m in v2.methods for s in v2.seeds
        if not (m == "BC" and r == "d64 L2")  # BC runs once, at the first rung
    ]  # fmt: skip
    table = ladder_table(v2, rows)
    view = ladder_view(table).set_index(["rung", "updates", "data set"])
    cell = view.loc[("d32 L1", 10_000, "hopper/medium")]
    assert cell["BC"] == "32.0 (3)" and cell["BC held to"] == pytest.approx(31.5, abs=0.1)
    assert (cell["level"], cell["targets"], cell["stable"], cell["passes"]) == ("yes",) * 4
    assert view.loc[("d64 L2", 30_000, "hopper/medium-replay"), "stable"] == ""  # the largest
    assert ladder_choice(table).startswith("Chosen: d32 L1 at 10,000 updates. d32 L1 @ 10,000")
    low = ladder_table(v2, [{**r, "score": r["score"] - 10} if r["method"] == "HDT" else r
                            for r in rows])  # fmt: skip
    assert set(ladder_view(low)["level"]) == {"no"}
    assert ladder_choice(low).startswith("No size chosen yet: d32 L1 @ 10,000: fails level")
    assert ladder_view(pd.DataFrame()).empty


def test_the_claims_page_plots_learning_curves_per_run_with_the_checkpoints_marked():
    import matplotlib

    matplotlib.use("Agg")
    from thesis_lib.chapters.claims import load_ladder_curves, plot_ladder_curves

    curves = pd.DataFrame(
        [
            {"dataset": "hopper/medium-replay", "rung": "d32 L1", "method": m, "seed": k,
             "updates": u, "score": 10.0 - u / 1000 * (m == "DM-noRTG")}
            for m in ("DM-noRTG", "DT") for k in (0, 1) for u in (1000, 2000, 3000)
        ]
    )  # fmt: skip
    fig = plot_ladder_curves(curves, checkpoints=(2000,))
    axes = fig.axes
    assert [a.get_title() for a in axes] == [
        "DM-noRTG, hopper/medium-replay, d32 L1",
        "DT, hopper/medium-replay, d32 L1",
    ]
    seed_lines = [ln for ln in axes[0].get_lines() if ln.get_label().startswith("seed")]
    assert len(seed_lines) == 2 and list(seed_lines[0].get_ydata()) == [9.0, 8.0, 7.0]
    assert any(list(ln.get_xdata()) == [2000, 2000] for ln in axes[0].get_lines())
    with pytest.raises(ValueError, match=r"lacks column\(s\) \['score'\]"):
        plot_ladder_curves(curves.drop(columns="score"))
    empty = plot_ladder_curves(curves.iloc[:0])
    assert empty.axes[0].texts[0].get_text() == "no learning curve stored yet"
    committed = load_ladder_curves()  # what the page reads (empty before any curve)
    assert committed.empty or {"updates", "score", "loss"} <= set(committed.columns)


def test_thesis_ladder_commit_every_commits_the_ladders_folder_and_nothing_else(
    tmp_path, monkeypatch, capsys
):
    """--commit-every: the runs and the table are committed as they land and at the end, as
    commits of ``studies/<name>/`` only; a user's own staged change stays staged."""
    import subprocess

    from thesis_lib.cli import main
    from thesis_lib.cli.ladder import commit_ladder

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=tmp_path, check=True, capture_output=True, text=True
        ).stdout

    (tmp_path / "_toc.yml").write_text("root: intro\n")
    (tmp_path / "params").mkdir()
    f = tmp_path / "params" / "mine.yml"
    f.write_text(BASE + "dataset_size: smoke\nepisodes: 1\ntrain: {warmup_steps: 2}\n")
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    with pytest.raises(SystemExit, match="not a git checkout"):  # said before any run
        main(["ladder", "-f", str(f), "--commit-every", "600"])
    assert not (tmp_path / "studies").exists()
    git("init", "-q")
    git("config", "user.name", "t")
    git("config", "user.email", "t@t")
    git("commit", "-q", "--allow-empty", "-m", "0")
    (tmp_path / "mine.txt").write_text("work in progress")
    git("add", "mine.txt")
    assert main(["ladder", "-f", str(f), "--commit-every", "3600"]) == 0
    assert git("log", "-1", "--format=%s").strip() == "mine: 2 finished run(s) landed (2/2)"
    committed = set(git("show", "--name-only", "--format=", "HEAD").split())
    assert "studies/mine/ladder.csv" in committed
    assert len([c for c in committed if c.startswith("studies/mine/tasks/")]) == 2
    assert not any(c.endswith(".lock") or ".tmp" in c for c in committed)
    assert git("diff", "--cached", "--name-only").split() == ["mine.txt"]  # still only staged
    assert commit_ladder(f, tmp_path / "studies" / "mine" / "tasks") is None  # nothing new
    # a run stored while the table is rewritten waits for the next commit, with its table
    import thesis_lib.cli.ladder as ladder_cli

    tasks = tmp_path / "studies" / "mine" / "tasks"
    late = sorted(tasks.glob("*.json"))[-1]
    held = late.read_text()
    git("rm", "-q", str(late))
    git("commit", "-q", "-m", "one run fewer")
    write_table = ladder_cli.write_ladder_table

    def landing(*args, **kwargs):
        out = write_table(*args, **kwargs)  # the table is made, then the run lands
        late.write_text(held)
        return out

    monkeypatch.setattr(ladder_cli, "write_ladder_table", landing)
    assert commit_ladder(f, tasks) == "mine: 0 finished run(s) landed (1/2)"
    assert late.name not in git("show", "--name-only", "--format=", "HEAD")
    monkeypatch.setattr(ladder_cli, "write_ladder_table", write_table)
    assert commit_ladder(f, tasks) == "mine: 1 finished run(s) landed (2/2)"
    curve = ["--curve", "hopper/medium", "d8 L1", "DT", "0", "--every", "4", "--to", "8"]
    assert main(["ladder", "-f", str(f), "--commit-every", "3600", *curve]) == 0
    assert git("log", "-1", "--format=%s").strip() == "mine: 1 learning curve(s) landed (2/2)"
    with pytest.raises(SystemExit, match="positive"):
        main(["ladder", "-f", str(f), "--commit-every", "0"])
    with pytest.raises(SystemExit, match="not inside the project"):
        main(["ladder", "-f", str(f), "--store", "/tmp/elsewhere", "--commit-every", "60"])
