"""The CLfD chapter's pre-registered study (claims C10-C12): its file, grid, tasks and section."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from thesis_lib.chapters import CHAPTERS
from thesis_lib.chapters import clfd as ex

REPO = Path(__file__).resolve().parents[1]


def test_study_file_parses_and_builds_its_grid(monkeypatch):
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study = st.load_study("02_clfd")
    assert study.study == "clfd-c10c12-v1" and study.metric == "neg_alignment_error"
    cfg = st.study_config(study, CHAPTERS["02_clfd"])
    assert cfg.n_demos == 150 and len(cfg.seeds) >= 5
    tasks = ex.study_tasks(cfg)
    by_fn: dict[str, list] = {}
    for t in tasks:
        by_fn.setdefault(t.fn.__name__, []).append(t.config)
    n = len(cfg.seeds)
    assert len(by_fn["study_alignment_task"]) == 2 * 3 * n  # encoders x methods x seeds
    assert len(by_fn["study_stage_task"]) == 2 * n  # CLfD and untrained features
    assert len(by_fn["study_rl_task"]) == 4 * n  # CLfD, CMC, TCN, untrained
    assert len(tasks) == 12 * n and len({t.key for t in tasks}) == len(tasks)
    for fn, configs in by_fn.items():
        assert {c["cfg"]["seed"] for c in configs} == set(cfg.seeds), fn
    # the stage and RL tasks need the TCN-style encoders: those train first
    first = by_fn["study_alignment_task"][: 3 * n]
    assert {c["encoder"] for c in first} == {"tcn"}
    assert [c["method"] for c in first[:3]] == ["clfd", "tcn", "cmc"]
    # every comparison names methods and settings the task functions label their rows with
    labels = {("CLfD", "PickPlace Resnet18"), ("CLfD", "PickPlace TCN")}
    labels |= {(m, s) for m in ("TCN", "CMC") for _, s in labels}
    labels |= {
        (p, f"stage ({f} TCN encoder)") for p in ex.STAGE_PROTOCOLS for f in ("CLfD", "untrained")
    }
    labels |= {(m, "RL pick (TCN encoder)") for m in ("CLfD", "TCN", "CMC", "untrained")}
    methods, settings = {m for m, _ in labels}, {s for _, s in labels}
    for c in study.comparisons:
        assert c["x"] in methods and c["y"] in methods, c
        assert set(c.get("settings") or []) <= settings, c
    assert {c["claim"] for c in study.comparisons} == {"C10", "C11", "C12"}
    check = st.study_config(study, CHAPTERS["02_clfd"], "check")
    assert check.epochs == 2 * cfg.epochs and check.encoders == ["tcn"]
    check_tasks = ex.study_tasks(check)
    assert {t.fn.__name__ for t in check_tasks} == {"study_alignment_task", "study_stage_task"}
    assert len(st.study_tasks(study, CHAPTERS["02_clfd"])) == len(tasks) + len(check_tasks)


def test_config_rejects_bad_study_fields():
    with pytest.raises(ValueError, match="seeds"):
        ex.Config(seeds=[0, 0])
    with pytest.raises(ValueError, match="rl_checkpoints"):
        ex.Config(rl_checkpoints=0)


def test_rl_success_curve_on_a_hand_made_run():
    ep = pd.DataFrame({"final_grip_box_distance": [0.5, 0.2, 0.02, 0.1, 0.01, 0.029]})
    assert ex.rl_success_curve(ep, 3, 0.03) == {
        "success_ep2": 0.0,
        "success_ep4": 0.5,
        "success_ep6": 1.0,
    }
    with pytest.raises(ValueError, match="checkpoints"):
        ex.rl_success_curve(ep, 7, 0.03)


def test_study_tasks_give_one_row_per_run_with_finite_numbers(clfd_tiny, tmp_path, monkeypatch):
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))  # the pinned encoders
    tiny = {
        **clfd_tiny,
        "rl_episodes": 4,
        "rl_checkpoints": 2,
        "rl_success_m": 10.0,  # every episode ends within 10 m of the box: success 1 by hand
        "seeds": [3],
    }
    tasks = ex.study_tasks(ex.Config(**tiny))
    assert len(tasks) == 2 + 2 + 2  # alignment x2, stage x2 (CLfD, untrained), RL x2
    rows = [r for t in tasks for r in t.fn(dict(t.config))]
    df = pd.DataFrame(rows)
    assert not df.duplicated(["method", "setting", "seed"]).any()
    assert set(df.seed) == {3} and set(df.scale) == {"study"}
    c10 = df[df.claim == "C10"]
    assert list(c10.method) == ["CLfD", "TCN"] and set(c10.setting) == {"PickPlace TCN"}
    assert c10.alignment_error_pct.between(0, 100).all()
    # the higher-is-better forms are the errors negated
    assert (c10.neg_alignment_error == -c10.alignment_error_pct).all()
    assert (c10.neg_val_alignment_error == -c10.val_best_pct).all()
    c11 = df[df.claim == "C11"]
    assert list(c11.method) == list(ex.STAGE_PROTOCOLS) * 2
    assert set(c11.features) == {"CLfD", "untrained"}
    assert c11.stage_accuracy.between(0, 100).all()
    c12 = df[df.claim == "C12"].set_index("method")
    assert list(c12.index) == ["CLfD", "untrained"]
    assert (c12.episodes == 4).all() and (c12.success_final == 1.0).all()
    assert {"success_ep2", "success_ep4"} <= set(c12.columns)
    numeric = df.select_dtypes("number")
    for col in ["alignment_error_pct", "stage_accuracy", "success_final", "final_distance_m"]:
        assert all(math.isfinite(v) for v in numeric[col].dropna()), col
    # the encoders were trained once and shared: two encoder tasks in the chapter's store
    store = tmp_path / "results" / "02_clfd" / "tasks"
    assert len(list(store.glob("*.json"))) == 2
    # ... and kept beside the study's rows; every row names the weights and frames it used
    pinned = tmp_path / "project" / "studies" / "02_clfd" / "encoders"
    assert len(list(pinned.glob("*.json"))) == len(list(pinned.glob("*.pt"))) == 2
    sha = dict(zip(c10.method, c10.encoder_sha))
    assert sha["CLfD"] != sha["TCN"] and len(sha["CLfD"]) == 16
    assert set(c11[c11.features == "CLfD"].encoder_sha) == {sha["CLfD"]}
    assert c11[c11.features == "untrained"].encoder_sha.isna().all()
    assert c12.loc["CLfD", "encoder_sha"] == sha["CLfD"]
    assert df.data_sha.dropna().nunique() == 1 and df[df.claim != "C12"].data_sha.notna().all()
    inputs = ex.summarize_study_inputs(df)
    assert inputs.to_dict("records") == [{"seed": 3, "data_sets": 1, "encoder_matches": "5/5"}]
    moved = df.copy()  # an RL row whose encoder is not the one its alignment task trained
    moved.loc[(moved.claim == "C12") & moved.encoder_sha.notna(), "encoder_sha"] = "0" * 16
    moved.loc[moved.claim == "C11", "data_sha"] = "1" * 16
    assert ex.summarize_study_inputs(moved).iloc[0].tolist() == [3, 2, "4/5"]
    assert ex.summarize_study_inputs(df.drop(columns="encoder_sha")).empty


def test_pinned_encoder_is_read_back_on_a_new_machine_not_trained_again(
    clfd_tiny, tmp_path, monkeypatch
):
    """A later session on a new machine (an empty encoder store) gets the weights the first
    one trained, from the study's folder, without training."""
    import shutil

    from thesis_lib.clfd.train import CLfD

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    cfg = ex.Config(**clfd_tiny)
    first, rows = ex.pinned_encoder(cfg, "tcn", "clfd")
    path = ex.model_path(dict(ex.encoder_task(cfg, "tcn", "clfd").config))
    trained = path.read_bytes()
    shutil.rmtree(tmp_path / "results")

    def no_training(*a, **k):
        raise AssertionError("trained the encoder again")

    monkeypatch.setattr(CLfD, "fit", no_training)
    again, rows_again = ex.pinned_encoder(cfg, "tcn", "clfd")
    assert path.read_bytes() == trained
    pd.testing.assert_frame_equal(
        rows.drop(columns="task_key", errors="ignore"),
        rows_again.drop(columns="task_key", errors="ignore"),
    )
    # a local encoder that differs from the pinned one is replaced by it
    path.write_bytes(b"not these weights")
    ex.pinned_encoder(cfg, "tcn", "clfd")
    assert path.read_bytes() == trained
    # another encoder is not in the folder: it would be trained
    with pytest.raises(AssertionError, match="trained the encoder again"):
        ex.pinned_encoder(cfg, "tcn", "tcn")


def _fake_rows(
    tasks: list,
    rng: np.random.Generator,
    untrained_error: float = 30.0,
    rl_success: dict[str, float] | None = None,
) -> pd.DataFrame:
    """Rows shaped as the study's task functions make them, without training: CLfD aligns
    better than TCN and CMC (an untrained encoder: ``untrained_error``), stage accuracy is the
    same on every camera set, and only the CLfD agent learns (``rl_success``: each RL
    method's final success instead, by its config name)."""
    rows = []
    for t in tasks:
        c, seed = t.config, t.config["cfg"]["seed"]
        base = {"seed": seed, "scale": c.get("scale", "study")}
        if t.fn is ex.study_alignment_control_task:
            ae = untrained_error + rng.normal(0, 0.5)
            enc = ex.ENCODER_LABELS[c["encoder"]]
            rows.append(
                base
                | {
                    "claim": "C10",
                    "method": "untrained",
                    "setting": f"PickPlace {enc}",
                    "encoder": enc,
                    "alignment_error_pct": ae,
                    "neg_alignment_error": -ae,
                }
            )
        elif t.fn is ex.study_alignment_task:
            ae = {"clfd": 8.0, "cmc": 12.0, "tcn": 15.0}[c["method"]] + rng.normal(0, 0.5)
            enc = ex.ENCODER_LABELS[c["encoder"]]
            rows.append(
                base
                | {
                    "claim": "C10",
                    "method": ex.METHOD_LABELS[c["method"]],
                    "setting": f"PickPlace {enc}",
                    "encoder": enc,
                    "alignment_error_pct": ae,
                    "neg_alignment_error": -ae,
                    "val_best_pct": ae - 1,
                    "neg_val_alignment_error": 1 - ae,
                }
            )
        elif t.fn is ex.study_stage_task:
            label = "CLfD" if c["features"] == "clfd" else "untrained"
            for p in ex.STAGE_PROTOCOLS:
                rows.append(
                    base
                    | {
                        "claim": "C11",
                        "method": p,
                        "setting": f"stage ({label} TCN encoder)",
                        "features": label,
                        "stage_accuracy": 95.0 + rng.normal(0, 0.5),
                    }
                )
        else:
            ok = 0.8 if c["method"] == "clfd" else 0.05
            if rl_success is not None:
                ok = rl_success[c["method"]]
            curve = {f"success_ep{k}": ok * k / 800 for k in range(80, 801, 80)}
            rows.append(
                base
                | {
                    "claim": "C12",
                    "method": ex.METHOD_LABELS.get(c["method"], c["method"]),
                    "setting": "RL pick (TCN encoder)",
                    "success_final": ok + rng.normal(0, 0.02),
                    "success_mean": ok / 2 + rng.normal(0, 0.02),
                    **curve,
                }
            )
    return pd.DataFrame(rows)


def test_the_study_files_comparisons_evaluate_on_a_full_grid_of_rows(monkeypatch):
    from thesis_lib.book import study as st
    from thesis_lib.stats.claims import claim_verdicts, evaluate_comparisons

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study = st.load_study("02_clfd")
    rows = _fake_rows(
        ex.study_tasks(st.study_config(study, CHAPTERS["02_clfd"])), np.random.default_rng(0)
    )
    res = evaluate_comparisons(rows, study.comparisons, metric=study.metric, reps=200)
    assert len(res) == len(study.comparisons) and res.verdict.notna().all()
    head = res.iloc[0]  # CLfD vs TCN over both encoders: 7 points less error
    assert head.effect == pytest.approx(7.0, abs=0.5) and head.verdict == "holds"
    verdicts = claim_verdicts(res).set_index("claim").verdict
    assert verdicts.to_dict() == {"C10": "holds", "C11": "holds", "C12": "holds"}
    t41, t42 = ex.compare_study_tables(rows, {"scale": "test"})
    ran = t41[t41["what differs"] != "not run"]
    assert len(ran) == 6 and (ran.seeds == 5).all() and (ran.ci_low <= ran.ours).all()
    assert set(t41.loc[t41["what differs"] == "not run", "dataset"]) == {"Pouring"}
    assert t42.dropna(subset=["paper"]).ours.between(90, 100).all()
    curves = ex.summarize_study_rl_curves(rows)
    assert set(curves.method) == {"CLfD", "TCN", "CMC", "untrained"}
    clfd = curves[curves.method == "CLfD"]
    assert list(clfd.episode) == list(range(80, 801, 80)) and (clfd.seeds == 5).all()
    assert clfd.success.iloc[-1] == pytest.approx(0.8)


def test_the_c10_study_runs_the_untrained_control_and_gates_on_it(monkeypatch):
    """clfd-c10-v2 (params/02_clfd.v4.study.yml): v1's alignment tasks, the same keys (reused),
    plus an untrained encoder per backbone and seed; a comparison whose trained method does not
    beat the untrained encoder is untestable, whatever its interval."""
    from thesis_lib.book import study as st
    from thesis_lib.stats.claims import claim_verdicts, evaluate_comparisons

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study, v1 = st.load_study("02_clfd:v4"), st.load_study("02_clfd")
    tasks = ex.study_tasks(st.study_config(study, CHAPTERS["02_clfd"]))
    v1_tasks = ex.study_tasks(st.study_config(v1, CHAPTERS["02_clfd"]))
    control = [t for t in tasks if t.fn is ex.study_alignment_control_task]
    assert len(control) == 2 * 5 and not any(
        t.fn is ex.study_alignment_control_task for t in v1_tasks
    )
    v1_align = {t.key for t in v1_tasks if t.fn is ex.study_alignment_task}
    assert {t.key for t in tasks if t not in control} == v1_align  # v1's runs, reused
    kw = dict(metric=study.metric, reps=200, interval="welch", gates=study.gates)

    def verdict(untrained_error: float) -> pd.DataFrame:
        rows = _fake_rows(tasks, np.random.default_rng(0), untrained_error)
        return evaluate_comparisons(rows, study.comparisons, **kw)

    floor_far = verdict(30.0)  # every method aligns far better than chance
    assert (floor_far.validity == "valid").all()
    assert claim_verdicts(floor_far).set_index("claim").verdict["C10"] == "holds"
    floor_near = verdict(12.5)  # TCN (15) and CMC (12) no better than an untrained encoder
    by = floor_near.set_index("label")
    assert (
        by.loc["CLfD vs TCN, -alignment error (points), both encoders", "verdict"] == "untestable"
    )
    assert (
        "control: TCN - untrained"
        in by.loc["CLfD vs TCN, -alignment error, ResNet-18 encoder", "gates"]
    )
    assert claim_verdicts(floor_near).set_index("claim").verdict["C10"] == "untestable"


def test_the_oracle_task_runs_without_an_encoder(clfd_tiny, tmp_path, monkeypatch):
    """C12's positive control through the study's RL task: no encoder is trained or read, and
    its row is shaped as the encoders' (the success measured on the true grasp point)."""
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path / "project"))
    tiny = {**clfd_tiny, "rl_episodes": 4, "rl_checkpoints": 2, "seeds": [3], "rl_oracle": True}
    tiny["study_claims"] = ["C12"]
    tasks = ex.study_tasks(ex.Config(**tiny))
    assert [t.config["method"] for t in tasks] == ["clfd", ex.UNTRAINED, ex.ORACLE]
    from thesis_lib.clfd.rl import GraspPointOracle

    reads = []
    real = GraspPointOracle.read_simulator
    monkeypatch.setattr(
        GraspPointOracle, "read_simulator", lambda self, env: reads.append(1) or real(self, env)
    )
    (row,) = tasks[-1].fn(dict(tasks[-1].config))
    assert row["method"] == "oracle" and row["encoder_sha"] is None and row["episodes"] == 4
    assert len(reads) > 4 * tiny["rl_steps"]  # every step's state came from the simulator
    assert 0.0 <= row["success_final"] <= 1.0 and math.isfinite(row["final_distance_m"])
    assert not (tmp_path / "project" / "studies").exists()  # no encoder pinned or trained
    off = ex.study_tasks(ex.Config(**{**tiny, "rl_oracle": False}))
    assert [t.key for t in off] == [t.key for t in tasks[:2]]  # the flag leaves other keys


def test_the_c12_study_adds_the_oracle_and_gates_on_it(monkeypatch):
    """clfd-c12-v4 (params/02_clfd.v5.study.yml): v3's RL tasks, the same keys (reused), plus
    the grasp-point oracle per seed. Where the oracle does not learn, every comparison is
    withheld; where it does, two encoders at the floor together are judged (v3 withheld them)."""
    from thesis_lib.book import study as st
    from thesis_lib.stats.claims import claim_verdicts, evaluate_comparisons

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study, v3 = st.load_study("02_clfd:v5"), st.load_study("02_clfd:v3")
    tasks = ex.study_tasks(st.study_config(study, CHAPTERS["02_clfd"]))
    v3_keys = {t.key for t in ex.study_tasks(st.study_config(v3, CHAPTERS["02_clfd"]))}
    oracle = [t for t in tasks if t.config["method"] == ex.ORACLE]
    assert len(oracle) == 5 and {t.key for t in tasks if t not in oracle} == v3_keys
    kw = dict(metric=study.metric, reps=200, interval="welch", gates=study.gates)

    def verdicts(oracle_success: float, v3_gates: bool = False) -> pd.DataFrame:
        floor = {"clfd": 0.0, "tcn": 0.0, "cmc": 0.0, "untrained": 0.0, "oracle": oracle_success}
        rows = _fake_rows(tasks, np.random.default_rng(0), rl_success=floor)
        return evaluate_comparisons(
            rows, study.comparisons, **{**kw, "gates": v3.gates if v3_gates else study.gates}
        )

    learns = verdicts(0.9)
    by = learns.set_index("label")
    head = "DDPG+HER with CLfD vs TCN features and reward, success in the last 20% of episodes"
    assert by.loc[head, "validity"] == "valid"
    assert "passed level: oracle success_final 0.9" in by.loc[head, "gates"]
    assert claim_verdicts(learns).set_index("claim").verdict["C12"] == "fails"  # no difference
    assert (verdicts(0.9, v3_gates=True).set_index("label").loc[head, "verdict"]) == "untestable"
    stuck = verdicts(0.2)  # even a perfect reward does not learn: nothing can be judged
    assert (stuck.verdict == "untestable").all()
    assert "oracle success_final 0.2" in stuck.set_index("label").loc[head, "gates"]


def test_the_c11_transfer_study_runs_new_seeds_and_gates_on_the_seen_accuracy(monkeypatch):
    """clfd-c11-v2 (params/02_clfd.v6.study.yml): stage tasks only, on seeds none of v1's; the
    transfer (seen -> unseen) decides; a seen-camera MLP near chance withholds the verdict."""
    from thesis_lib.book import study as st
    from thesis_lib.stats.claims import claim_verdicts, evaluate_comparisons

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    study, v1 = st.load_study("02_clfd:v6"), st.load_study("02_clfd")
    tasks = ex.study_tasks(st.study_config(study, CHAPTERS["02_clfd"]))
    v1_keys = {t.key for t in ex.study_tasks(st.study_config(v1, CHAPTERS["02_clfd"]))}
    assert {t.fn for t in tasks} == {ex.study_stage_task} and len(tasks) == 2 * 5
    assert {t.config["cfg"]["seed"] for t in tasks} == {5, 6, 7, 8, 9}
    assert not {t.key for t in tasks} & v1_keys

    def verdict(seen: float, transfer: float) -> str:
        rows = _fake_rows(tasks, np.random.default_rng(0))
        clfd = rows["features"] == "CLfD"
        rows.loc[clfd & (rows["method"] == "Seen"), "stage_accuracy"] += seen - 95.0
        rows.loc[clfd & (rows["method"] == "Seen->Unseen"), "stage_accuracy"] += transfer - 95.0
        out = evaluate_comparisons(
            rows, study.comparisons, metric=study.metric, reps=200, interval="welch",
            gates=study.gates,
        )  # fmt: skip
        return claim_verdicts(out).set_index("claim").verdict["C11"]

    assert verdict(seen=72.0, transfer=71.0) == "holds"
    assert verdict(seen=72.0, transfer=52.0) == "fails"
    assert verdict(seen=52.0, transfer=50.0) == "untestable"  # nothing to transfer


def test_the_c10_study_reads_on_the_secondary_metric_without_its_control(monkeypatch):
    """The untrained control has no best validation checkpoint (the secondary metric): its
    comparison is left out of the secondary reading, the others are judged on it."""
    from thesis_lib.book import evidence as evi

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    ev = evi.load_evidence(CHAPTERS["02_clfd"], study="v4", reps=200)
    assert ev.complete
    sec = evi.secondary_comparisons(ev, reps=200)
    assert len(sec) == len(ev.study.comparisons) - 1
    assert "untrained" not in set(sec["y"])
    (reading,) = evi.claim_readings(ev, reps=200).to_dict("records")
    assert reading["claim"] == "C10" and reading["on the thesis's metric"] != "pending"


def test_the_c10_control_task_measures_an_untrained_encoder(clfd_tiny):
    """The control task's row: the untrained encoder's test alignment error, as Table 4.1's
    floor row measures it, with no validation history."""
    cfg = ex.Config(
        **{**clfd_tiny, "seeds": [3], "alignment_controls": True, "study_claims": ["C10"]}
    )
    tasks = [t for t in ex.study_tasks(cfg) if t.fn is ex.study_alignment_control_task]
    assert len(tasks) == 1  # one backbone in the tiny config
    (row,) = tasks[0].fn(dict(tasks[0].config))
    assert row["method"] == "untrained" and row["claim"] == "C10" and row["seed"] == 3
    assert 0 <= row["alignment_error_pct"] <= 100
    assert row["neg_alignment_error"] == -row["alignment_error_pct"]
    assert math.isnan(row["val_best_pct"]) and row["data_sha"]
    cfg3 = ex.Config(**{**clfd_tiny, "seed": 3})
    model = ex.build_model(cfg3, tasks[0].config["encoder"], "clfd")
    floor = ex.alignment_numbers(cfg3, ex.load_data(cfg3), model)
    assert row["alignment_error_pct"] == pytest.approx(floor["alignment_error_pct"])


def test_study_section_renders_before_the_study_ran(unstarted_study):
    from thesis_lib.book import evidence as evi

    ev = unstarted_study("02_clfd")
    assert ex.summarize_study_rl_curves(ev.rows).empty
    ex.plot_study_rl_curves(ex.summarize_study_rl_curves(ev.rows))
    t41, t42 = ex.compare_study_tables(ev.rows, {"scale": "test"})
    assert (t41["what differs"] == "not run").all() and len(t41) == 12
    assert (t42["what differs"] == "not run").all() and len(t42) == 3
    for metric in (None, "stage_accuracy", "success_final", "success_mean"):
        evi.plot_per_setting(ev, metric)
        evi.plot_comparisons(ev, metric)
    assert set(evi.claim_readings(ev).ours) == {"pending"}


def test_claims_page_links_c10_to_c12_to_this_chapters_study_section():
    from thesis_lib.chapters.claims import ledger_table, link_chapters

    ledger = ledger_table(pd.DataFrame({"claim": ["C10"], "verdict": ["pending"]}))
    linked = link_chapters(ledger).set_index("claim").chapter
    for c in ("C10", "C11", "C12"):
        assert linked[c] == '<a href="02_clfd.html#evidence-at-study-scale">02_clfd</a>'
    nb = (REPO / "notebooks" / "02_clfd.ipynb").read_text()
    assert "## Evidence at study scale" in nb


def test_study_tables_render_mid_study_before_any_alignment_row(monkeypatch):
    """Mid-study, with only stage-classification rows committed, the thesis-beside-us tables
    still build (Table 4.1 empty of ours, Table 4.2 filled) instead of a KeyError."""
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    tasks = ex.study_tasks(st.study_config(st.load_study("02_clfd"), CHAPTERS["02_clfd"]))
    stage = [t for t in tasks if t.fn is ex.study_stage_task][:1]
    rows = _fake_rows(stage, np.random.default_rng(0))
    assert "encoder" not in rows
    t41, t42 = ex.compare_study_tables(rows, {"data": "d", "scale": "s"})
    assert t41["seeds"].isna().all() and t42["seeds"].notna().any()


def test_a_study_of_one_claim_runs_only_its_tasks_with_the_same_keys(monkeypatch):
    """``study_claims: [C12]`` (clfd-c12-v2): only the RL tasks, each with the key it has in
    the full grid at the same config (the encoders come from the chapter's store)."""
    from thesis_lib.book import study as st

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    cfg = st.study_config(st.load_study("02_clfd"), CHAPTERS["02_clfd"])
    full = ex.study_tasks(cfg)
    rl = ex.study_tasks(ex.Config(**{**cfg.__dict__, "study_claims": ["C12"]}))
    assert rl and all(t.fn is ex.study_rl_task for t in rl)
    assert [t.key for t in rl] == [t.key for t in full if t.fn is ex.study_rl_task]
    for bad in (["C13"], [], "C12"):
        with pytest.raises(ValueError, match="study_claims"):
            ex.Config(study_claims=bad)
