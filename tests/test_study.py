"""Pre-registered studies: parameter file -> sweep -> committed rows -> claims.csv."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import types
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from thesis_lib.book import study as st
from thesis_lib.book.chapter import Chapter
from thesis_lib.chapters import CHAPTERS
from thesis_lib.sweep import Task, TaskFailed

CALLS: list[str] = []
FAIL: set[str] = set()  # runs that raise, as "method/setting/seed"


def fake_task(cfg: dict) -> list[dict]:
    """A 'training run': method HDT scores 10 above DT, seeds add noise."""
    run = f"{cfg['method']}/{cfg['setting']}/{cfg['seed']}"
    CALLS.append(run)
    if run in FAIL:
        raise FloatingPointError(f"{run} diverged")
    base = {"HDT": 60.0, "DT": 50.0}[cfg["method"]] + cfg["offset"]
    return [{**cfg, "score": base + (cfg["seed"] % 3) - 1.0}]


@dataclass
class FakeConfig:
    settings: list[str] = field(default_factory=lambda: ["a", "b"])
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    offset: float = 0.0


def fake_study_tasks(cfg: FakeConfig) -> list[Task]:
    return [
        Task(fake_task, {"method": m, "setting": s, "seed": k, "offset": cfg.offset})
        for m in ("HDT", "DT")
        for s in cfg.settings
        for k in cfg.seeds
    ]


STUDY = {
    "study": "fake-v1",
    "chapter": "04_hdt",
    "description": "a test study",
    "config": {"seeds": [0, 1, 2, 3, 4], "offset": 1.0},
    "metric": "score",
    "comparisons": [
        {"claim": "C3", "x": "HDT", "y": "DT", "kind": "superior", "margin": 2.0},
        {"claim": "C2", "x": "DT", "y": "HDT", "kind": "noninferior", "margin": 2.0},
    ],
}


@pytest.fixture
def project(tmp_path, monkeypatch):
    (tmp_path / "_toc.yml").write_text("root: intro\n")
    (tmp_path / "notebooks").mkdir()
    (tmp_path / "params").mkdir()
    (tmp_path / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(STUDY))
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    mod = types.SimpleNamespace(Config=FakeConfig, study_tasks=fake_study_tasks)
    for name in ("04_hdt", "05_decision_mamba"):  # the fake chapter's code under both names
        monkeypatch.setitem(CHAPTERS, name, Chapter(name, Path(__file__), lambda: mod))
    CALLS.clear()
    FAIL.clear()
    return tmp_path


def test_study_runs_resumes_and_records_its_hash(project):
    rows = st.run_study(CHAPTERS["04_hdt"], progress=False)
    assert len(rows) == 2 * 2 * 5 and len(CALLS) == 20
    info = json.loads((project / "studies" / "04_hdt" / "run.json").read_text())
    assert info["complete"] and info["tasks_done"] == 20
    assert info["study_hash"] == st.load_study("04_hdt").hash
    assert len(list((project / "studies" / "04_hdt" / "tasks").glob("*.json"))) == 20
    # a second run finds every task stored and runs none
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    assert len(CALLS) == 20
    csv = pd.read_csv(project / "studies" / "04_hdt" / "rows.csv")
    assert sorted(csv["method"].unique()) == ["DT", "HDT"]


def test_run_json_names_the_versions_its_tasks_ran_with(project):
    """Tasks run on another machine (the GPU study's) and summarised here: run.json's
    ``versions`` are the latest task's, not the summarising process's."""
    study = st.load_study("04_hdt")
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    files = sorted((project / "studies" / "04_hdt" / "tasks").glob("*.json"))
    for i, f in enumerate(files):
        rec = json.loads(f.read_text())
        rec["versions"] = {"python": "3.12.3", "torch": f"2.11.{i}"}
        rec["stored_utc"] = f"2026-11-28T21:{i:02d}:00+00:00"
        f.write_text(json.dumps(rec))
    keys = [t.key for t in st.study_tasks(study, CHAPTERS["04_hdt"])]
    info = st.write_study_summary(study, keys)
    assert info["versions"] == {"python": "3.12.3", "torch": f"2.11.{len(files) - 1}"}


def test_verdicts_follow_from_the_rows(project):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    res = st.evaluate_study("04_hdt", reps=500)
    c3 = res[res.claim == "C3"].iloc[0]
    assert c3.effect == pytest.approx(10.0) and c3.verdict == "holds"
    c2 = res[res.claim == "C2"].iloc[0]
    assert c2.verdict == "fails"  # DT is 10 worse: far outside the 2-point margin
    claims = st.write_claims(CHAPTERS, reps=500)
    assert len(claims) == 14 and list(claims.claim[:3]) == ["C1", "C2", "C3"]
    got = claims.set_index("claim").verdict
    assert (got["C3"], got["C2"], got["C1"]) == ("holds", "fails", "pending")
    assert (project / "studies" / "claims.csv").exists()


def test_an_unfinished_study_is_pending_not_judged(project, monkeypatch):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    info_p = project / "studies" / "04_hdt" / "run.json"
    info = json.loads(info_p.read_text())
    info_p.write_text(json.dumps({**info, "complete": False, "tasks_done": 7}))
    with pytest.raises(RuntimeError, match="not complete"):
        st.evaluate_study("04_hdt")
    claims = st.write_claims(CHAPTERS, reps=200).set_index("claim")
    assert claims.verdict["C3"] == "pending" and "7/20" in claims.comparisons["C3"]


def test_a_changed_study_file_does_not_reuse_old_rows(project):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    changed = {**STUDY, "config": {**STUDY["config"], "offset": 2.0}}
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(changed))
    new = st.load_study("04_hdt")
    assert st.study_rows(new).empty  # old task files carry the old study hash


V2 = {
    **STUDY,
    "study": "fake-v2",
    "supersedes": "fake-v1",
    "config": {"seeds": [0, 1, 2], "offset": 3.0},
    # the claim turned round (DT better than HDT), so that its verdict differs from v1's
    "comparisons": [{"claim": "C3", "x": "DT", "y": "HDT", "kind": "superior", "margin": 2.0}],
}


def test_a_later_study_runs_beside_the_first_and_takes_over_its_claims_once_complete(project):
    """params/<chapter>.<tag>.study.yml: its own folder, hash and rows; the first study keeps
    its rows and verdicts, and claims.csv shows both (history) and the last complete one's."""
    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump(V2))
    v1, v2 = st.chapter_studies("04_hdt")
    assert (v1.ref, v2.ref, v2.tag) == ("04_hdt", "04_hdt:v2", "v2")
    assert v2.folder == project / "studies" / "04_hdt" / "v2"
    assert v2.file == "params/04_hdt.v2.study.yml" and v1.hash != v2.hash
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    claims = st.write_claims(CHAPTERS, reps=200).set_index("claim")
    # v2 pending: the first study still answers C3, and the history says v2 is on its way
    assert claims.loc["C3", "study"] == "fake-v1" and claims.loc["C3", "verdict"] == "holds"
    assert claims.loc["C3", "history"] == "fake-v1: holds; fake-v2: pending, 0/12 tasks"
    assert claims.loc["C2", "history"] == "fake-v1: fails"
    CALLS.clear()
    st.run_study(CHAPTERS["04_hdt"], study="v2", progress=False)
    assert len(CALLS) == 12  # its own tasks (another offset: other keys), none of v1's
    info = json.loads((v2.folder / "run.json").read_text())
    assert info["complete"] and info["supersedes"] == "fake-v1"
    assert info["study_file"] == "params/04_hdt.v2.study.yml"
    assert len(st.study_rows(v1)) == 20 and len(st.study_rows(v2)) == 12
    claims = st.write_claims(CHAPTERS, reps=200).set_index("claim")
    # HDT - DT = 10 < the v2 margin of 20: v2 decides C3 now, v1's verdict stays in the history
    assert claims.loc["C3", "study"] == "fake-v2" and claims.loc["C3", "verdict"] != "holds"
    assert claims.loc["C3", "history"].startswith("fake-v1: holds; fake-v2: ")
    assert claims.loc["C2", "study"] == "fake-v1"  # v2 does not register C2
    from thesis_lib.chapters.claims import ledger_table

    ours = ledger_table(claims.reset_index()).set_index("claim").ours
    assert ours["C3"].endswith("(studies: fake-v1: holds; fake-v2: fails)")
    assert "studies:" not in ours["C2"]
    # the Claims page's v1-beside-v2 table
    from thesis_lib.chapters.claims import studies_table

    side = studies_table(claims.reset_index()).set_index("claim")
    assert side.loc["C3", ["v1 study", "v1", "v2 study", "v2"]].tolist() == [
        "fake-v1", "holds", "fake-v2", "fails",
    ]  # fmt: skip
    assert side.loc["C2", ["v1", "v2 study"]].tolist() == ["fails", "none registered yet"]
    assert side.loc["C14", "v1 study"] == "no study yet"  # no study file registers it here
    # evidence of either study, by tag
    from thesis_lib.book import evidence as evi

    assert evi.load_evidence(CHAPTERS["04_hdt"], reps=200, study="v2").study.study == "fake-v2"
    assert evi.load_evidence(CHAPTERS["04_hdt"], reps=200).study.study == "fake-v1"


def test_a_study_replaced_before_it_completed_says_where_it_stopped(project):
    """v2 registered, then v3 (a control added) replaces it before v2 completed: v2 is
    listed as superseded with its progress, never as pending again; v1 answers until v3 is
    complete, and the Claims page's later study is v3."""
    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump(V2))
    v3 = {**V2, "study": "fake-v3", "supersedes": "fake-v2"}
    (project / "params" / "04_hdt.v3.study.yml").write_text(yaml.safe_dump(v3))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    claims = st.write_claims(CHAPTERS, reps=200).set_index("claim")
    assert claims.loc["C3", "history"] == (
        "fake-v1: holds; fake-v2: superseded by fake-v3 at 0/12 tasks; fake-v3: pending, 0/12 tasks"
    )
    assert claims.loc["C3", ["study", "verdict"]].tolist() == ["fake-v1", "holds"]
    from thesis_lib.chapters.claims import studies_table

    side = studies_table(claims.reset_index()).set_index("claim")
    assert side.loc["C3", ["v2 study", "v2"]].tolist() == ["fake-v3", "pending, 0/12 tasks"]
    # v2's evidence section says it stopped, not that it is in progress; v3's that it runs
    from thesis_lib.book import evidence as evi

    v2 = st.load_study("04_hdt:v2")
    st.run_study(CHAPTERS["04_hdt"], study=v2, progress=False)
    keys = [t.key for t in st.study_tasks(v2, CHAPTERS["04_hdt"])]
    (v2.folder / "tasks" / f"{keys[0]}.json").unlink()  # as if replaced after 11 of 12
    st.write_study_summary(v2, keys)
    line = evi.status_line(evi.load_evidence(CHAPTERS["04_hdt"], reps=200, study="v2"))
    assert "11/12 tasks (stopped: superseded by fake-v3)" in line
    assert st.superseded_by(st.load_study("04_hdt:v3")) is None
    st.run_study(CHAPTERS["04_hdt"], study="v3", progress=False)
    line = evi.status_line(evi.load_evidence(CHAPTERS["04_hdt"], reps=200, study="v3"))
    assert "12/12 tasks (complete)" in line


def test_a_study_read_beside_another_is_listed_in_the_history_and_decides_nothing(project):
    """`beside:` (C6's GPU timings beside the CPU study): its verdicts go to ``history``, with
    ", beside <id>", never to the claim's verdict, also while the study it is beside is the
    only other one; the Claims page's v1/v2 table leaves it out."""
    aside = {**V2, "study": "fake-gpu", "beside": "fake-v1"}
    del aside["supersedes"]
    (project / "params" / "04_hdt.gpu.study.yml").write_text(yaml.safe_dump(aside))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    st.run_study(CHAPTERS["04_hdt"], study="gpu", progress=False)
    info = json.loads((project / "studies" / "04_hdt" / "gpu" / "run.json").read_text())
    assert info["complete"] and info["beside"] == "fake-v1" and "supersedes" not in info
    claims = st.write_claims(CHAPTERS, reps=200).set_index("claim")
    # fake-gpu finds DT not better than HDT (fails), but fake-v1's verdict stays the claim's
    assert claims.loc["C3", "study"] == "fake-v1" and claims.loc["C3", "verdict"] == "holds"
    assert claims.loc["C3", "history"] == "fake-v1: holds; fake-gpu: fails, beside fake-v1"
    from thesis_lib.chapters.claims import studies_table

    side = studies_table(claims.reset_index()).set_index("claim")
    assert side.loc["C3", ["v1 study", "v2 study"]].tolist() == [
        "fake-v1", "none registered yet",
    ]  # fmt: skip


@pytest.mark.parametrize(
    "patch, message",
    [
        ({"beside": "fake-v9"}, "`beside: fake-v9` names no other study of 04_hdt"),
        ({"beside": "fake-v1", "supersedes": "fake-v1"}, "not both"),
        ({"beside": ["fake-v1"]}, "Expect `beside` to be the id of a study"),
    ],
)
def test_a_wrong_beside_is_refused_at_load(project, patch, message):
    (project / "params" / "04_hdt.gpu.study.yml").write_text(
        yaml.safe_dump({**STUDY, "study": "fake-gpu", **patch})
    )
    with pytest.raises(ValueError, match=re.escape(message)):
        st.load_study("04_hdt:gpu")


def test_thesis_study_names_a_later_study_by_tag_or_file(project, capsys):
    from thesis_lib.cli import main

    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump(V2))
    assert main(["study", "04_hdt:v2", "--status"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["study"], out["tasks_total"]) == ("fake-v2", 12)
    assert main(["study", str(project / "params" / "04_hdt.v2.study.yml")]) == 0
    assert len(CALLS) == 12 and (project / "studies" / "04_hdt" / "v2" / "rows.csv").is_file()
    assert not (project / "studies" / "04_hdt" / "rows.csv").exists()  # v1 untouched
    assert main(["study", "--status"]) == 0  # every registered study, first to last
    out = capsys.readouterr().out
    assert out.index('"study": "fake-v1"') < out.index('"study": "fake-v2"')
    with pytest.raises(SystemExit, match="only --status"):
        main(["study"])
    assert main(["study", "04_hdt:V2"]) == 1
    assert "A study tag is lower-case" in capsys.readouterr().err
    assert main(["study", "04_hdt:v3"]) == 1
    assert "No study file" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("patch", "match"),
    [
        ({"supersedes": "hdt-v0"}, "names no earlier study of 04_hdt"),
        ({"supersedes": 2}, "Expect `supersedes` to be the id of an earlier study"),
        ({"chapter": "05_decision_mamba"}, "named unlike its `chapter: 05_decision_mamba`"),
    ],
)
def test_a_later_study_file_names_an_earlier_study_and_its_own_chapter(project, patch, match):
    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump({**V2, **patch}))
    with pytest.raises(ValueError, match=match):
        st.load_study("04_hdt:v2")


def _git_checkout(project):
    """Make ``project`` a git checkout with one empty commit; returns ``git(*args) -> stdout``."""
    import subprocess

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=project, check=True, capture_output=True, text=True
        ).stdout

    git("init", "-q")
    git("config", "user.name", "t")
    git("config", "user.email", "t@t")
    git("commit", "-q", "--allow-empty", "-m", "0")
    return git


def test_committing_a_first_study_leaves_its_later_studies_rows_alone(project):
    from thesis_lib.cli import study as study_cli

    git = _git_checkout(project)
    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump(V2))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    st.run_study(CHAPTERS["04_hdt"], study="v2", progress=False)
    assert study_cli.commit_studies(["04_hdt"]).startswith("studies: 20 finished task(s)")
    files = git("show", "--name-only", "--format=", "HEAD").split()
    assert files and not any(f.startswith("studies/04_hdt/v2/") for f in files)
    assert study_cli.commit_studies(["04_hdt:v2"]).startswith("studies: 12 finished task(s)")
    files = git("show", "--name-only", "--format=", "HEAD").split()
    assert all(f.startswith("studies/04_hdt/v2/") or f == "studies/claims.csv" for f in files)


def test_a_commit_lands_the_tasks_when_another_study_file_cannot_be_read(project, capsys):
    """A long run commits with the code it started with; a study file written since, with a
    key that code does not know, stops claims.csv's rebuild but not the tasks' commit."""
    from thesis_lib.cli import study as study_cli

    git = _git_checkout(project)
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    (project / "params" / "04_hdt.v2.study.yml").write_text(
        yaml.safe_dump({**V2, "a_key_from_the_future": 1})
    )
    msg = study_cli.commit_studies(["04_hdt"])
    assert msg.startswith("studies: 20 finished task(s)")
    assert "claims.csv not rebuilt" in msg and "a_key_from_the_future" in msg
    files = git("show", "--name-only", "--format=", "HEAD").split()
    assert len([f for f in files if f.startswith("studies/04_hdt/tasks/")]) == 20
    assert "studies/claims.csv" not in files
    assert "claims.csv not rebuilt" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("patch", "match"),
    [
        ({"seeds_per_setting": 5}, "unknown study key"),
        ({"comparisons": []}, "no comparison"),
        ({"comparisons": [{"claim": "C99", "x": "a", "y": "b"}]}, "unknown claim"),
        ({"comparisons": [{"claim": "C1", "x": "a", "y": "b", "kind": "better"}]}, "kind"),
        ({"comparisons": [{"claim": "C1", "x": "a"}]}, "lacks 'y'"),
    ],
)
def test_bad_study_files_are_errors(patch, match):
    with pytest.raises(ValueError, match=match):
        st.parse_study({**STUDY, **patch})


def test_unknown_config_field_is_an_error(project):
    bad = {**STUDY, "config": {"seedz": [0]}}
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(bad))
    with pytest.raises(ValueError, match="Unknown parameter 'seedz'"):
        st.study_tasks(st.load_study("04_hdt"), CHAPTERS["04_hdt"])


def test_scale_check_runs_beside_the_study_and_stays_out_of_the_verdicts(project):
    checked = {
        **STUDY,
        "scale_check": {"config": {"settings": ["a"], "seeds": [0, 1, 2], "offset": -40.0}},
    }
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(checked))
    rows = st.run_study(CHAPTERS["04_hdt"], progress=False)
    assert len(CALLS) == 20 + 2 * 3  # the study's 20 runs and the check's 6
    check = rows[rows["scale"] == "check"]
    assert len(check) == 6 and set(check["setting"]) == {"a"}
    # the check's runs (offset -40, far below) would move the effect if they were counted
    res = st.evaluate_study("04_hdt", reps=300)
    assert res[res.claim == "C3"].iloc[0].effect == pytest.approx(10.0)


def test_reuse_copies_the_same_tasks_from_another_study(project, monkeypatch):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    other = {**STUDY, "study": "fake-05-v1", "chapter": "05_decision_mamba", "reuse": ["04_hdt"]}
    (project / "params" / "05_decision_mamba.study.yml").write_text(yaml.safe_dump(other))
    CALLS.clear()
    rows = st.run_study(CHAPTERS["05_decision_mamba"], progress=False)
    assert CALLS == [] and len(rows) == 20  # every task was the 04 study's: none trained again
    rec = json.loads(
        next((project / "studies" / "05_decision_mamba" / "tasks").glob("*.json")).read_text()
    )
    assert rec["study"] == "fake-05-v1" and rec["reused_from"]["chapter"] == "04_hdt"
    assert st.write_study_summary(st.load_study("05_decision_mamba"), list(rows.task_key.unique()))[
        "complete"
    ]


def test_a_comparison_reported_apart_does_not_decide_the_claim(project):
    apart = {
        **STUDY,
        "comparisons": [
            {"claim": "C3", "x": "HDT", "y": "DT", "kind": "superior"},
            {"claim": "C3", "x": "DT", "y": "HDT", "kind": "superior", "counts": False},
        ],
    }
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(apart))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    res = st.evaluate_study("04_hdt", reps=300)
    assert list(res.verdict) == ["holds", "fails"]
    claims = st.write_claims(CHAPTERS, reps=300).set_index("claim")
    assert claims.verdict["C3"] == "holds" and "reported apart" in claims.comparisons["C3"]


def test_bad_scale_check_is_an_error():
    with pytest.raises(ValueError, match="scale_check"):
        st.parse_study({**STUDY, "scale_check": {"settings": ["a"]}})


REPO = Path(__file__).resolve().parents[1]
COMMITTED = sorted(
    [*(REPO / "studies").glob("*/run.json"), *(REPO / "studies").glob("*/*/run.json")]
)


@pytest.mark.skipif(not COMMITTED, reason="no study committed yet")
@pytest.mark.parametrize("run_json", COMMITTED, ids=lambda p: p.parent.name)
def test_committed_studies_match_their_parameter_files(run_json, monkeypatch):
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    info = json.loads(run_json.read_text())
    study = st.load_study(REPO / info["study_file"])
    assert run_json.parent == REPO / "studies" / study.chapter / study.tag
    assert info["study_hash"] == study.hash, (
        f"{run_json} was computed from another {info['study_file']}: the study file changed "
        "after the study started (start a new study id instead)"
    )


COMPLETE = [
    json.loads(p.read_text())["study_file"]
    for p in COMMITTED
    if json.loads(p.read_text()).get("complete")
]


@pytest.mark.skipif(not COMPLETE, reason="no complete study committed yet")
def test_committed_claims_follow_from_the_committed_rows(monkeypatch):
    """studies/claims.csv holds, for every complete study, what the rule gives on its rows."""
    from thesis_lib.stats.claims import claim_verdicts

    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    committed = pd.read_csv(REPO / "studies" / "claims.csv").set_index("claim")
    deciding = {}  # each claim's verdict comes from the last complete study that registers it
    for file in COMPLETE:
        for c in st.load_study(REPO / file).comparisons:
            deciding[c["claim"]] = file
    for file in dict.fromkeys(deciding.values()):
        study = st.load_study(REPO / file)
        for r in claim_verdicts(st.evaluate_study(study)).itertuples():
            if deciding[r.claim] != file:
                continue
            c = committed.loc[r.claim]
            assert (c.chapter, c.study) == (study.chapter, study.study), (r.claim, "thesis claims")
            assert c.verdict == r.verdict, (r.claim, "run thesis claims")
            assert c.effect == pytest.approx(r.effect) and c.ci_low == pytest.approx(r.ci_low)
            assert c.ci_high == pytest.approx(r.ci_high)
            assert (c.kind, c.margin) == (r.kind, pytest.approx(r.margin))


def test_committed_claims_list_every_registered_study_of_a_claim(monkeypatch):
    """``history`` names every study file that registers the claim, first to last: a study file
    added without ``thesis claims`` is caught here."""
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(REPO))
    committed = pd.read_csv(REPO / "studies" / "claims.csv").set_index("claim")
    want: dict[str, list[str]] = {}
    for f in st.study_files():
        study = st.load_study(f)
        for claim in dict.fromkeys(c["claim"] for c in study.comparisons):
            want.setdefault(claim, []).append(study.study)
    for claim, studies in want.items():
        got = [h.split(":")[0] for h in str(committed.loc[claim, "history"]).split("; ")]
        assert got == studies, (claim, "run thesis claims")


READING = re.compile(
    r"\*\*Reading the verdicts\*\* \(study `([^`]+)`, complete: (\d+) runs, ([\d.]+) CPU-hours"
)
SAID = re.compile(r"\*\*(C\d+)[ ,]+(holds|fails|inconclusive|untestable)\b")
READ_BY_HAND = [
    p
    for p in sorted((REPO / "notebooks").glob("*.ipynb"))
    if "Reading the verdicts" in p.read_text(encoding="utf-8")
]


@pytest.mark.parametrize("notebook", READ_BY_HAND, ids=lambda p: p.stem)
def test_hand_written_readings_quote_the_committed_study_and_verdicts(notebook):
    """Each hand-written "Reading the verdicts" of a chapter (one per study it reads: the first,
    and a second study's beside it) names its study as committed and gives each claim the
    verdict that study has in studies/claims.csv (its ``history``): the prose cannot drift from
    the rows."""
    import nbformat

    cells = [c.source for c in nbformat.read(notebook, 4).cells if c.cell_type == "markdown"]
    texts = [c for c in cells if "Reading the verdicts" in c]
    assert texts
    runs = {}
    for f in [REPO / "studies" / notebook.stem / "run.json",
              *(REPO / "studies" / notebook.stem).glob("*/run.json")]:  # fmt: skip
        if f.is_file():
            info = json.loads(f.read_text())
            runs[info["study"]] = info
    claims = pd.read_csv(REPO / "studies" / "claims.csv")
    mine = claims[claims.chapter == notebook.stem]
    by_study: dict[str, dict[str, str]] = {}
    for claim, history in zip(mine.claim, mine.history):
        for study, status in st.history_entries(history):
            by_study.setdefault(study, {})[claim] = status.split(",")[0]
    for text in texts:
        m = READING.search(text)
        assert m, f"{notebook.name}: a reading must start with its study id, runs and CPU-hours"
        info = runs.get(m[1])
        assert info is not None, f"{notebook.name}: no committed run.json of study {m[1]}"
        assert info["complete"]
        assert int(m[2]) == info["tasks_total"] and float(m[3]) == round(info["cpu_hours"], 1)
        # every claim the study decides is read, each with that study's verdict
        assert dict(SAID.findall(text)) == by_study[m[1]], m[1]
    # the claim's verdict (the latest complete study's) is read somewhere on the page
    read = {m[1] for m in map(READING.search, texts) if m}
    assert set(mine.study) <= read


# ------------------------------------------------------------------ a chapter's evidence section


def test_evidence_section_before_during_and_after_the_study(project):
    import matplotlib

    matplotlib.use("Agg")
    from thesis_lib.book import evidence as evi

    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    assert "not run yet" in evi.status_line(ev) and ev.rows.empty
    assert set(evi.comparisons_table(ev).verdict) == {"pending"}
    evi.plot_per_setting(ev)  # an empty study still draws (a note)

    st.run_study(CHAPTERS["04_hdt"], progress=False)
    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    assert ev.complete and "20/20 tasks (complete)" in evi.status_line(ev)
    table = evi.per_setting_table(ev)
    hdt_a = table[(table.method == "HDT") & (table.setting == "a")].iloc[0]
    # seeds 0-4 add -1, 0, 1, -1, 0 to HDT's 60 + offset 1: mean 60.8
    assert hdt_a["mean"] == pytest.approx(60.8) and hdt_a.seeds == 5
    assert hdt_a.ci_low <= 60.8 <= hdt_a.ci_high
    comp = evi.comparisons_table(ev)
    assert list(comp.verdict) == ["holds", "fails"]
    assert comp.effect.iloc[0] == pytest.approx(10.0)
    fig = evi.plot_comparisons(ev)
    assert len(fig.axes[0].get_yticks()) == 2
    evi.plot_per_setting(ev)


def test_input_versions_counts_rows_and_seeds_per_hash(project):
    from thesis_lib.book import evidence as evi

    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    assert list(evi.input_versions(ev, "data_sha").columns) == ["data_sha", "rows", "seeds"]
    assert evi.input_versions(ev, "data_sha").empty  # not run yet
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    assert evi.input_versions(ev, "data_sha").empty  # its rows do not record one
    n = len(ev.rows)
    ev.rows["data_sha"] = np.where(ev.rows["seed"] >= 3, "b", "a")
    ev.rows.loc[ev.rows.index[ev.rows.seed == 1][0], "data_sha"] = None
    got = evi.input_versions(ev, "data_sha")
    a_rows = int((ev.rows.seed < 3).sum()) - 1
    assert got.rows.sum() == n and got.data_sha.iloc[0] == "a" and got.rows.iloc[0] == a_rows
    assert got.set_index("data_sha").loc["b", "seeds"] == "3,4"
    assert got.set_index("data_sha").loc["not recorded"].tolist() == [1, "1"]


def test_scale_check_table_ranks_both_scales(project):
    from thesis_lib.book import evidence as evi

    checked = {
        **STUDY,
        "scale_check": {"config": {"settings": ["a"], "seeds": [0, 1, 2], "offset": 5.0}},
    }
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(checked))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    t = evi.scale_check_table(evi.load_evidence(CHAPTERS["04_hdt"], reps=200)).set_index("method")
    assert t.loc["HDT", "check"] == pytest.approx(65.0)  # 60 + 5, seeds 0-2 add -1, 0, 1
    assert t.loc["HDT", "rank (study)"] == t.loc["HDT", "rank (check)"] == 1
    assert t.loc["DT", "seeds (check)"] == 3
    low = evi.scale_check_table(
        evi.load_evidence(CHAPTERS["04_hdt"], reps=200), higher_is_better=False
    ).set_index("method")  # a measure where less is better (crashes): the order turns over
    assert (low["rank (check)"] == len(low) + 1 - t["rank (check)"].reindex(low.index)).all()


def test_thesis_study_runs_several_in_order_and_status_writes_nothing_before_a_run(project, capsys):
    from thesis_lib.cli import main

    other = {**STUDY, "study": "fake-05-v1", "chapter": "05_decision_mamba"}
    (project / "params" / "05_decision_mamba.study.yml").write_text(yaml.safe_dump(other))
    assert main(["study", "04_hdt", "05_decision_mamba", "--status"]) == 0
    assert '"tasks_done": 0' in capsys.readouterr().out
    assert not (project / "studies").exists()  # --status on unstarted studies leaves no files
    assert main(["study", "04_hdt", "06_nope"]) == 1  # a typo fails before any study runs
    assert "No study file" in capsys.readouterr().err and not CALLS
    assert main(["study", "04_hdt", "05_decision_mamba"]) == 0
    assert len(CALLS) == 2 * 20  # both grids, one after the other
    for ch in ("04_hdt", "05_decision_mamba"):
        assert json.loads((project / "studies" / ch / "run.json").read_text())["complete"]
    main(["study", "04_hdt", "--status"])
    assert '"tasks_done": 20' in capsys.readouterr().out


def test_thesis_study_chooses_mujocos_headless_back_end_before_any_study_imports_it(
    project, monkeypatch
):
    """One `thesis study` process runs 03 (simulation only) and then 02 (rendered frames): MuJoCo
    reads MUJOCO_GL once, at its first import, so the command sets it first, as a chapter's
    kernel gets it; a value the user chose stays."""
    from thesis_lib.cli import main

    monkeypatch.delenv("MUJOCO_GL", raising=False)
    assert main(["study", "04_hdt", "--status"]) == 0
    assert os.environ["MUJOCO_GL"] == "egl"
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    assert main(["study", "04_hdt", "--status"]) == 0
    assert os.environ["MUJOCO_GL"] == "osmesa"


def test_thesis_study_keep_going_runs_the_rest_and_the_next_study(project, capsys, monkeypatch):
    from thesis_lib.cli import main

    other = {**STUDY, "study": "fake-05-v1", "chapter": "05_decision_mamba"}
    (project / "params" / "05_decision_mamba.study.yml").write_text(yaml.safe_dump(other))
    FAIL.update({"DT/a/0", "HDT/b/4"})  # both studies have these runs
    with pytest.raises(TaskFailed, match="HDT/b/4 diverged"):  # no flag: the first stops all
        main(["study", "04_hdt", "05_decision_mamba"])
    assert len(CALLS) == 10  # HDT's a and b seeds, in grid order, then it stopped
    info = json.loads((project / "studies" / "04_hdt" / "run.json").read_text())
    assert info["tasks_done"] == 9  # the summary of what finished is written anyway
    CALLS.clear()
    assert main(["study", "04_hdt", "05_decision_mamba", "--keep-going"]) == 1
    err = capsys.readouterr().err
    assert len(CALLS) == 20 - 9 + 20  # every run not stored yet, of both studies, was tried
    assert "04_hdt: 2 of 20 task(s) failed" in err and "05_decision_mamba: 2 of 20" in err
    assert "Failed tasks in: 04_hdt (2 task(s)), 05_decision_mamba (2 task(s))" in err
    info = json.loads((project / "studies" / "04_hdt" / "run.json").read_text())
    assert info["tasks_done"] == 18 and not info["complete"]
    reads = []
    real_records = st.task_records
    monkeypatch.setattr(
        st, "task_records", lambda *a, **k: reads.append(1) or real_records(*a, **k)
    )
    assert main(["study", "04_hdt", "--status"]) == 0
    assert len(reads) == 1  # the task files are read once, however many numbers use them
    status = json.loads(capsys.readouterr().out)
    assert len(status["tasks_failed"]) == 2
    left = status["cpu_hours"] / 18 * 2  # two tasks left, at the mean cost of the 18 done
    assert status["cpu_hours_left_estimate"] == pytest.approx(left, abs=0.05)
    assert "checkpoints" not in status  # neither unfinished task saved one
    # an unfinished task with a training checkpoint (partial/<key>/step-<n>/) is listed with
    # its newest step; a finished task's leftover folder is not
    tasks = st.study_tasks(st.load_study("04_hdt"), CHAPTERS["04_hdt"])
    store = project / "studies" / "04_hdt" / "tasks"
    todo = [t for t in tasks if not (store / f"{t.key}.json").exists()]
    for t, steps in ((todo[0], (2000, 4000)), (tasks[0], (1000,))):
        for n in steps:
            (store / "partial" / t.key / f"step-{n:010d}").mkdir(parents=True)
    main(["study", "04_hdt", "--status"])
    (ckpt,) = json.loads(capsys.readouterr().out)["checkpoints"]
    assert ckpt["task"] == todo[0].key and ckpt["checkpoint_step"] == 4000
    assert ckpt["method"] == todo[0].config["method"] and ckpt["updated"].startswith("20")
    FAIL.clear()  # fixed: a rerun runs only the failed tasks, and forgets their failures
    CALLS.clear()
    assert main(["study", "04_hdt", "--keep-going"]) == 0
    assert sorted(CALLS) == ["DT/a/0", "HDT/b/4"]
    # before the bar can time a task, the run says what is left at the finished tasks' cost
    err = capsys.readouterr().err
    assert "study fake-v1: 2 task(s) to run, about " in err and "CPU-hours" in err
    main(["study", "04_hdt", "--status"])
    assert "tasks_failed" not in json.loads(capsys.readouterr().out)


def test_thesis_study_commit_every_commits_the_studies_and_nothing_else(project, capsys):
    """--commit-every: finished tasks are committed as the run goes and at its end, as commits
    of studies/<chapter>/ and studies/claims.csv only; a user's own staged change stays staged."""
    import subprocess

    from thesis_lib.cli import main
    from thesis_lib.cli import study as study_cli

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=project, check=True, capture_output=True, text=True
        ).stdout

    with pytest.raises(SystemExit):  # not a checkout yet: said before any task runs
        main(["study", "04_hdt", "--commit-every", "600"])
    assert CALLS == []
    git("init", "-q")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "--allow-empty", "-m", "0")
    git("config", "user.name", "t")
    git("config", "user.email", "t@t")
    (project / "mine.txt").write_text("work in progress")
    git("add", "mine.txt")
    FAIL.add("HDT/b/4")
    assert main(["study", "04_hdt", "--commit-every", "3600", "--keep-going"]) == 1
    log = git("log", "--format=%s").splitlines()
    assert log[0] == "studies: 19 finished task(s) landed (fake-v1 19/20)"
    committed = set(git("show", "--name-only", "--format=", "HEAD").split())
    assert len([f for f in committed if "/tasks/" in f]) == 19
    assert "studies/claims.csv" in committed and "studies/04_hdt/run.json" in committed
    assert not any("failed" in f or f.endswith(".tmp") for f in committed)
    assert git("diff", "--cached", "--name-only").split() == ["mine.txt"]  # still only staged
    # the rerun that completes the study commits its last task and the verdicts it decides
    FAIL.clear()
    assert main(["study", "04_hdt", "--commit-every", "3600"]) == 0
    assert git("log", "-1", "--format=%s").strip() == (
        "studies: 1 finished task(s) landed (fake-v1 20/20)"
    )
    claims = pd.read_csv(io.StringIO(git("show", "HEAD:studies/claims.csv")))
    assert claims.set_index("claim").loc["C3", "verdict"] == "holds"
    # nothing new: no commit; a refused commit is reported, not raised
    assert study_cli.commit_studies(["04_hdt"]) is None
    (project / ".git" / "index.lock").write_text("")
    (project / "studies" / "04_hdt" / "note.txt").write_text("x")
    study_cli._Committer(["04_hdt"], 3600).commit()
    assert "commit skipped: git add failed" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="positive"):
        main(["study", "04_hdt", "--commit-every", "0"])


def test_a_run_landing_during_a_commit_waits_for_the_next_one(project, monkeypatch):
    """A run stored while ``commit_studies`` refreshes the summaries is not in its rows.csv, so
    it is not committed with them: the commit's count and rows.csv agree, and the next commit
    takes the run with the rows.csv that has it (seen on defender-c7c9-v6 12/36: a commit of
    one new task whose rows.csv still had 12 rows)."""
    from thesis_lib.cli import main
    from thesis_lib.cli import study as study_cli

    git = _git_checkout(project)
    FAIL.add("HDT/b/4")
    assert main(["study", "04_hdt", "--keep-going"]) == 1  # 19 of 20 stored, none committed
    tasks = project / "studies" / "04_hdt" / "tasks"
    late = sorted(tasks.glob("*.json"))[-1]
    held = late.read_text()
    late.unlink()  # stored "later": while the first commit refreshes the summaries
    write_claims = st.write_claims

    def landing(*args, **kwargs):
        late.write_text(held)
        return write_claims(*args, **kwargs)

    monkeypatch.setattr(st, "write_claims", landing)
    msg = study_cli.commit_studies(["04_hdt"])
    assert msg == "studies: 18 finished task(s) landed (fake-v1 18/20)"
    committed = git("show", "--name-only", "--format=", "HEAD").split()
    assert f"studies/04_hdt/tasks/{late.name}" not in committed
    assert len(pd.read_csv(io.StringIO(git("show", "HEAD:studies/04_hdt/rows.csv")))) == 18
    monkeypatch.setattr(st, "write_claims", write_claims)
    assert study_cli.commit_studies(["04_hdt"]) == (
        "studies: 1 finished task(s) landed (fake-v1 19/20)"
    )
    assert f"studies/04_hdt/tasks/{late.name}" in git("show", "--name-only", "--format=", "HEAD")


def test_status_line_says_what_changed_in_the_library_since_the_study(project, monkeypatch):
    import subprocess

    from thesis_lib.book import evidence as evi

    def git(*args: str) -> None:
        subprocess.run(
            ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
            cwd=project, check=True, capture_output=True,
        )  # fmt: skip

    st.run_study(CHAPTERS["04_hdt"], progress=False)  # outside git: commit "unknown"
    assert evi.code_changes_since(evi.load_evidence(CHAPTERS["04_hdt"], reps=100)) is None
    assert "changed" not in evi.status_line(evi.load_evidence(CHAPTERS["04_hdt"], reps=100))
    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "study code")
    st.run_study(CHAPTERS["04_hdt"], progress=False, force=True)  # now at that commit
    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=100)
    assert evi.code_changes_since(ev).empty
    assert "The code its tasks run has not changed since." in evi.status_line(ev)
    lib = project / "src" / "thesis_lib"
    lib.mkdir(parents=True)
    (lib / "model.py").write_text("x = 1\n")
    git("add", "-A")
    git("commit", "-qm", "change the model")
    (project / "notes.md").write_text("prose\n")  # not the library: not listed
    (lib / "book").mkdir()
    (lib / "book" / "page.py").write_text("y = 2\n")  # the book's rendering: not listed
    git("add", "-A")
    git("commit", "-qm", "prose and rendering")
    since = evi.code_changes_since(ev)  # the task function is not library code: all of it counts
    assert list(since.subject) == ["change the model"]
    assert "Since then, 1 commit(s) changed the code its tasks run" in evi.status_line(ev)
    assert "except as the uncommitted" not in evi.status_line(ev)
    assert "Its study file" not in evi.status_line(ev)
    dirty = dataclasses.replace(ev, info={**ev.info, "commits": [ev.info["commits"][0] + "-dirty"]})
    line = evi.status_line(dirty)  # run on an uncommitted tree (the GPU study's copy)
    assert f"run at commit(s) {ev.info['commits'][0][:7]} with uncommitted changes." in line
    assert "took no part in these rows, except as the uncommitted changes" in line
    older = dataclasses.replace(  # an older commit was dirty, the newest clean: no caveat
        ev, info={**ev.info, "commits": [ev.info["commits"][0], "0" * 40 + "-dirty"]}
    )
    assert "except as the uncommitted" not in evi.status_line(older)
    study_file = project / "params" / "04_hdt.study.yml"
    study_file.write_text(study_file.read_text() + "# a note\n")
    git("commit", "-qam", "the study file")
    since = evi.code_changes_since(ev)
    assert list(since.subject) == ["the study file", "change the model"]
    assert list(since.changed) == ["study file", "code"]
    line = evi.status_line(ev)  # the file's commit is not counted as a change of the code
    assert "Since then, 1 commit(s) changed the code its tasks run (newest" in line
    assert "Its study file (params/04_hdt.study.yml) was written or changed since, at 1" in line

    # a task function in the library: only the modules it runs count
    def write(rel: str, text: str) -> None:
        (lib / rel).parent.mkdir(parents=True, exist_ok=True)
        (lib / rel).write_text(text)

    write("__init__.py", "")
    write("chapters/__init__.py", "")
    write("chapters/fake.py", "from thesis_lib.m import f\n\ndef run(c):\n    from ..n import g\n")
    write("m.py", "def f(): ...\n")
    write("n/__init__.py", "from .x import g\n")
    write("n/x.py", "def g(): ...\n")
    write("n/unused.py", "z = 0\n")
    git("add", "-A")
    git("commit", "-qm", "the library's layout")
    assert evi.study_code_paths({"thesis_lib.chapters.fake"}, project) == [
        f"src/thesis_lib/{f}"
        for f in ["__init__.py", "chapters/__init__.py", "chapters/fake.py", "m.py",
                  "n/__init__.py", "n/x.py"]
    ]  # fmt: skip
    st.run_study(CHAPTERS["04_hdt"], progress=False, force=True)  # at HEAD
    monkeypatch.setattr(st, "study_task_functions", lambda study: {"thesis_lib.chapters.fake:run"})
    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=100)
    for rel, subject in [("n/x.py", "lazily imported"), ("n/unused.py", "not imported"),
                         ("model.py", "not imported either"), ("chapters/fake.py", "the task")]:  # fmt: skip
        write(rel, (lib / rel).read_text() + "# changed\n")
        git("add", "-A")
        git("commit", "-qm", subject)
    assert list(evi.code_changes_since(ev).subject) == ["the task", "lazily imported"]


def test_claim_readings_say_where_we_differ_and_why(project):
    from thesis_lib.book import evidence as evi

    assert set(evi.claim_readings(evi.load_evidence(CHAPTERS["04_hdt"], reps=200)).ours) == {
        "pending"
    }
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    read = evi.claim_readings(evi.load_evidence(CHAPTERS["04_hdt"], reps=200), reps=200).set_index(
        "claim"
    )
    assert read.loc["C3", "ours"] == "holds" and "may differ" not in read.loc["C3", "reading"]
    assert (
        read.loc["C2", "ours"] == "fails" and "may differ because of" in read.loc["C2", "reading"]
    )
    assert "the data" in read.loc["C2", "reading"]
    own = evi.claim_readings(
        evi.load_evidence(CHAPTERS["04_hdt"], reps=200),
        reps=200,
        claim_notes={"C2": "the hardware"},
    ).set_index("claim")
    assert "the hardware" in own.loc["C2", "reading"] and "the data" not in own.loc["C2", "reading"]
    assert own.loc["C3", "reading"] == read.loc["C3", "reading"]
    with pytest.raises(ValueError, match="C9"):
        evi.claim_readings(evi.load_evidence(CHAPTERS["04_hdt"], reps=200), claim_notes={"C9": "x"})


def test_claim_readings_name_the_comparison_that_decided_the_verdict(project):
    from thesis_lib.book import evidence as evi

    two = {
        **STUDY,
        "comparisons": [
            {"claim": "C3", "x": "HDT", "y": "DT", "kind": "superior", "margin": 2.0},
            {"claim": "C3", "x": "DT", "y": "HDT", "kind": "superior", "label": "the other way"},
            {"claim": "C2", "x": "HDT", "y": "DT", "kind": "superior", "margin": 2.0},
        ],
    }
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump(two))
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    read = evi.claim_readings(evi.load_evidence(CHAPTERS["04_hdt"], reps=200), reps=200).set_index(
        "claim"
    )
    # C3's headline (HDT vs DT, +10) holds, but its second comparison fails: so does C3
    c3 = read.loc["C3", "reading"]
    assert read.loc["C3", "ours"] == "fails" and "effect 10 [" in c3
    assert "Decided by the other way (score): fails, effect -10 [" in c3
    assert "Decided by" not in read.loc["C2", "reading"]  # its headline is its verdict
    # claims.csv and the Claims page's ledger say it too
    from thesis_lib.chapters.claims import ledger_table

    claims = st.write_claims(CHAPTERS, reps=200)
    by = pd.read_csv(project / "studies" / "claims.csv").set_index("claim")
    assert by.loc["C3", "decided_by"].startswith("the other way (score): fails, effect -10 [")
    assert pd.isna(by.loc["C2", "decided_by"])
    ours = ledger_table(claims).set_index("claim").ours
    assert "; decided by the other way (score): fails" in ours["C3"]
    assert "decided by" not in ours["C2"]


def test_claims_plot_gives_each_claim_its_own_axis_and_its_margin():
    """Effects in different units get their own axes; the margin that decides is drawn."""
    from thesis_lib.chapters.claims import plot_claims

    def row(claim, verdict, effect, lo, hi, kind, margin, comparisons):
        return dict(
            claim=claim,
            verdict=verdict,
            effect=effect,
            ci_low=lo,
            ci_high=hi,
            kind=kind,
            margin=margin,
            comparisons=comparisons,
            decided_by=np.nan,
        )

    claims = pd.DataFrame(
        [
            row(
                "C1",
                "inconclusive",
                -1.0,
                -6.0,
                4.0,
                "superior",
                5.0,
                "DT vs DT-noRTG (score_final): inconclusive [-6, 4]",
            ),
            row(
                "C4",
                "holds",
                0.5,
                -2.0,
                3.0,
                "noninferior",
                5.0,
                "DM-noRTG vs DM-RTG (score_final): holds [-2, 3]",
            ),
            row(
                "C6",
                "fails",
                -140.0,
                -156.0,
                -127.0,
                "superior",
                0.0,
                "DM-noRTG vs DT (act_per_s_window): fails [-156, -127]; DM vs DT (act_per_s): holds",
            ),
            row("C7", "pending", np.nan, np.nan, np.nan, None, np.nan, "0/126 tasks done"),
        ]
    )
    fig = plot_claims(claims)
    c1, c4, c6 = fig.axes  # the pending claim has no panel
    for ax, (lo, hi) in zip(fig.axes, [(-6, 5), (-5, 3), (-156, 0)]):
        assert ax.get_xlim()[0] < lo and ax.get_xlim()[1] > hi
    assert c1.get_xlim()[0] > -10  # not stretched to C6's actions per second
    assert c1.get_title(loc="left") == "DT vs DT-noRTG (score_final)"
    assert c6.get_title(loc="left") == "DM-noRTG vs DT (act_per_s_window)"
    assert c6.get_yticklabels()[0].get_text() == "C6\nfails"
    assert len(c1.patches) == 1 and not c4.patches and not c6.patches  # superior's band
    assert [ln.get_xdata()[0] for ln in c4.lines if ln.get_linestyle() == "--"] == [-5.0]
    empty = plot_claims(claims[claims.verdict == "pending"])
    assert empty.axes[0].texts[0].get_text() == "no claim judged yet"


def test_aggregate_table_and_performance_profiles(project):
    import matplotlib

    matplotlib.use("Agg")
    from thesis_lib.book import evidence as evi

    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    assert evi.aggregate_table(ev).empty  # nothing ran: nothing to aggregate
    evi.plot_performance_profiles(ev)  # still draws (a note)
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    ev = evi.load_evidence(CHAPTERS["04_hdt"], reps=200)
    t = evi.aggregate_table(ev, reps=200).set_index("method")
    # HDT: 61 + (-1, 0, 1, -1, 0) in both settings: mean 60.8; the IQM drops 2 scores at
    # each end of the 10 (sorted 60 60 60 60 61 61 61 61 62 62): mean of 60 60 61 61 61 61
    assert t.loc["HDT", "mean"] == pytest.approx(60.8)
    assert t.loc["HDT", "iqm"] == pytest.approx(364 / 6)
    assert t.loc["DT", "mean"] == pytest.approx(50.8)
    assert (t.runs == 10).all() and (t.settings == 2).all()
    assert (t.iqm_low <= t.iqm).all() and (t.iqm <= t.iqm_high).all()
    fig = evi.plot_performance_profiles(ev, reps=100)
    assert len(fig.axes[0].lines) == 2


def test_the_estimate_of_cpu_hours_left_prices_each_task_like_its_finished_kin(project):
    """A grid's tasks differ in cost: an unfinished task is priced at the mean of the finished
    ones of its method (and scale), not at the mean of all of them."""
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    study = st.load_study("04_hdt")
    tasks = st.study_tasks(study, CHAPTERS[study.chapter])
    store = project / "studies" / "04_hdt" / "tasks"
    for t in tasks:  # HDT runs took 360 s, DT runs 36 s
        p = store / f"{t.key}.json"
        rec = json.loads(p.read_text())
        p.write_text(json.dumps({**rec, "cpu_s": 360.0 if t.config["method"] == "HDT" else 36.0}))
    assert st.cpu_hours_left(study, tasks) == 0.0
    hdt = [t for t in tasks if t.config["method"] == "HDT"]
    dt = [t for t in tasks if t.config["method"] == "DT"]
    for t in hdt[:2] + dt[:3]:
        (store / f"{t.key}.json").unlink()
    assert st.cpu_hours_left(study, tasks) == pytest.approx((2 * 360 + 3 * 36) / 3600)
    for t in dt:  # no DT run finished: DT is priced at what the function's runs cost
        (store / f"{t.key}.json").unlink(missing_ok=True)
    assert st.cpu_hours_left(study, tasks) == pytest.approx((2 * 360 + 10 * 360) / 3600)
    for t in hdt:
        (store / f"{t.key}.json").unlink(missing_ok=True)
    assert st.cpu_hours_left(study, tasks) == 0.0  # nothing finished: no basis for a price


def _label_run(config):
    return [config]


def test_the_estimate_prices_tasks_that_name_their_method_label_by_it():
    """The DEFENDER chapter's tasks say ``label``, not ``method``: a filtered run is priced at
    the filtered runs' cost, not at the mean of plain and filtered ones."""
    from thesis_lib.sweep import fn_path

    run = _label_run

    def task(label, seed):
        return Task(run, {"label": label, "seed": seed})

    done = [task("SAC", 0), task("SAC+filter", 0)]
    todo = [task("SAC", 1), task("SAC+filter", 1), task("SAC+filter", 2), task("SAC+random", 1)]
    records = [
        {"key": done[0].key, "fn": fn_path(run), "config": done[0].config, "cpu_s": 3600.0},
        {"key": done[1].key, "fn": fn_path(run), "config": done[1].config, "cpu_s": 10800.0},
    ]
    # plain 1 h, filtered 3 h each, the control (no finished kin) at the mean of all: 2 h
    # (priced all alike, the four would be 8 h)
    assert st.cpu_hours_left(None, done + todo, records=records) == pytest.approx(9.0)


# ------------------------------------------------------------------ issue #37: study boundaries


def test_a_second_runner_skips_the_tasks_another_holds_and_takes_over_dead_ones(project, capsys):
    """Two `thesis study` of one chapter at once: a task another process holds (its
    `tasks/<key>.lock`) is skipped, not run twice; the lock of a process that died is taken."""
    import subprocess
    import sys

    keys = [t.key for t in st.study_tasks(st.load_study("04_hdt"), CHAPTERS["04_hdt"])]
    store = project / "studies" / "04_hdt" / "tasks"
    store.mkdir(parents=True)
    locks = [str(store / f"{k}.lock") for k in keys[:5]]
    holder = subprocess.Popen(  # another runner, busy with the first five tasks
        [sys.executable, "-c", "import fcntl, os, sys, time\n"
         "fs = [open(p, 'w') for p in sys.argv[1:]]\n"
         "for f in fs: fcntl.flock(f, fcntl.LOCK_EX); f.write(f'pid {os.getpid()}'); f.flush()\n"
         "print('held', flush=True); time.sleep(120)", *locks],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        rows = st.run_study(CHAPTERS["04_hdt"], progress=False)
        assert len(CALLS) == 15 and len(rows) == 15  # the other runner's five were not run
        assert f"skipping 5 task(s) another run holds, e.g. {locks[0]} (pid {holder.pid}" in (
            capsys.readouterr().err
        )
        assert sorted(p.name for p in store.glob("*.lock")) == sorted(Path(p).name for p in locks)
    finally:
        holder.kill()  # it dies holding its locks: their files stay behind
        holder.wait()
    assert all(Path(p).exists() for p in locks)
    CALLS.clear()
    st.run_study(CHAPTERS["04_hdt"], progress=False)  # the dead runner's tasks are taken over
    assert len(CALLS) == 5 and not list(store.glob("*.lock"))
    assert json.loads((project / "studies" / "04_hdt" / "run.json").read_text())["complete"]


def test_thesis_study_takes_its_study_files_path_and_refuses_a_misnamed_one(
    project, capsys, monkeypatch
):
    from thesis_lib.cli import main

    monkeypatch.chdir(project)
    assert main(["study", "params/04_hdt.study.yml", "--status"]) == 0
    assert '"tasks_done": 0' in capsys.readouterr().out
    assert main(["study", str(project / "params" / "04_hdt.study.yml")]) == 0
    assert len(CALLS) == 20 and (project / "studies" / "04_hdt" / "rows.csv").is_file()
    # a study file outside params/ is not the registered study: refused, nothing runs
    (project / "elsewhere").mkdir()
    (project / "elsewhere" / "04_hdt.study.yml").write_text(yaml.safe_dump(STUDY))
    assert main(["study", "elsewhere/04_hdt.study.yml"]) == 1
    assert "is not a registered study of 04_hdt" in capsys.readouterr().err
    # a file named unlike its chapter would write its tasks where no one reads them
    (project / "params" / "04_hdx.study.yml").write_text(yaml.safe_dump(STUDY))
    CALLS.clear()
    for args in (["04_hdx", "--status"], ["params/04_hdx.study.yml"], ["04_hdt", "04_hdx"]):
        assert main(["study", *args]) == 1
        err = capsys.readouterr().err
        assert "04_hdx.study.yml is named unlike its `chapter: 04_hdt`" in err
    assert CALLS == [] and not (project / "studies" / "04_hdx").exists()


@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"config": {"seeds": 3}}, "Expect `seeds` to be a list of ints, actually: 3 (config in"),
        ({"config": {"offset": "lots"}}, "Expect `offset` to be a number, actually: 'lots'"),
        ({"config": {"settings": ["a", 1]}}, "Expect `settings` to be a list of strings"),
        (
            {"scale_check": {"config": {"seeds": "0-2"}}},
            "Expect `seeds` to be a list of ints, actually: '0-2' (scale_check.config in",
        ),
        ({"metric": "scroe"}, "Expect `metric` to be a column of the 04_hdt study's rows, "),
        ({"secondary": "best"}, "Expect `secondary` to be a column of"),
        ({"columns": {"seed": "run"}}, "Expect `columns.seed` to be a column of"),
        (
            {"comparisons": [{**STUDY["comparisons"][0], "margin": "half"}]},
            "Expect `margin` of comparison C3 (HDT vs DT) to be a number >= 0, actually: 'half'",
        ),
        ({"metric": ["score"]}, "Expect `metric` to be a column name, actually: ['score']"),
    ],
)
def test_bad_study_values_name_their_key_before_anything_runs(
    project, capsys, monkeypatch, patch, message
):
    from thesis_lib.cli import main

    mod = types.SimpleNamespace(
        Config=FakeConfig,
        study_tasks=fake_study_tasks,
        STUDY_COLUMNS=["method", "setting", "seed", "offset", "score"],
    )
    monkeypatch.setitem(CHAPTERS, "04_hdt", Chapter("04_hdt", Path(__file__), lambda: mod))
    (project / "params" / "04_hdt.study.yml").write_text(yaml.safe_dump({**STUDY, **patch}))
    assert main(["study", "04_hdt", "--status"]) == 1
    err = capsys.readouterr().err
    assert message in err and "params/04_hdt.study.yml" in err and "Traceback" not in err
    assert main(["study", "04_hdt"]) == 1 and CALLS == []


def test_the_hdt_study_checks_its_values_and_metrics_against_the_chapter():
    """The real chapter: its Config's types and its declared STUDY_COLUMNS."""
    data = yaml.safe_load((REPO / "params" / "04_hdt.study.yml").read_text())
    st.study_config(st.parse_study(data), CHAPTERS["04_hdt"])  # the registered study passes
    for patch, message in [
        ({"config": {**data["config"], "iterations": "lots"}}, "`iterations` to be an int"),
        ({"metric": "score_finl"}, "`metric` to be a column of the 04_hdt study's rows"),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            st.study_config(st.parse_study({**data, **patch}), CHAPTERS["04_hdt"])


@pytest.mark.parametrize("file", st.study_files(), ids=lambda p: p.name)
def test_every_registered_study_declares_its_columns_and_passes_the_check(file):
    """Only the HDT chapter declared STUDY_COLUMNS, so no other study's metrics were checked;
    every study file, a later one too, builds its chapter's Config and its tasks."""
    study = st.load_study(file)
    columns = CHAPTERS[study.chapter].study_columns
    assert len(columns) == len(set(columns)) and {"method", "setting", "seed"} <= set(columns)
    st.study_config(study, CHAPTERS[study.chapter])  # the study file names real columns
    if study.tag:  # a later study: what it supersedes (or is read beside) exists, and its
        # tasks are not v1's
        assert (study.supersedes or study.beside) in {
            s.study for s in st.chapter_studies(study.chapter)
        }
        first = st.load_study(study.chapter)
        keys = {t.key for t in st.study_tasks(study, CHAPTERS[study.chapter])}
        shared = keys & {t.key for t in st.study_tasks(first, CHAPTERS[study.chapter])}
        # ... unless the file says it reuses v1's runs (clfd-c10-v2: v1's alignment runs)
        assert not shared or study.chapter in study.reuse


def test_a_misspelt_ur3_metric_is_refused_at_load_naming_it(tmp_path):
    """`metric: goals_meen` was accepted: the study would run and the claims read no column."""
    data = yaml.safe_load((REPO / "params" / "07_ur3_deployment.study.yml").read_text())
    copy = tmp_path / "07_ur3_deployment.study.yml"
    copy.write_text(yaml.safe_dump({**data, "metric": "goals_meen"}))
    with pytest.raises(ValueError) as err:
        st.study_config(st.load_study(copy), CHAPTERS["07_ur3_deployment"])
    said = str(err.value)
    assert "`metric` to be a column of the 07_ur3_deployment study's rows" in said
    assert "'goals_meen'" in said and str(copy) in said and "goals_mean" in said


@pytest.mark.parametrize(
    ("damage", "what"),
    [
        (lambda row: row.update(score=float("nan")), "has no score (NaN or missing)"),
        (lambda row: row.pop("score"), "has no score (NaN or missing)"),
        (lambda row: row.update(score="n/a"), "has score 'n/a', not a number"),
        (lambda row: row.pop("seed"), "has no seed"),
    ],
    ids=["nan", "missing", "text", "no-seed"],
)
def test_claims_name_the_task_file_of_a_bad_row(project, damage, what):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    task = next(
        t
        for t in st.study_tasks(st.load_study("04_hdt"), CHAPTERS["04_hdt"])
        if t.config["method"] == "HDT"
    )
    path = project / "studies" / "04_hdt" / "tasks" / f"{task.key}.json"
    rec = json.loads(path.read_text())
    damage(rec["rows"][0])
    path.write_text(json.dumps(rec))
    with pytest.raises(ValueError) as err:
        st.write_claims(CHAPTERS, reps=100)  # what `thesis claims` runs
    assert f"studies/04_hdt/tasks/{task.key}.json" in str(err.value) and what in str(err.value)


def test_claims_refuse_rows_without_a_seed_column(project):
    st.run_study(CHAPTERS["04_hdt"], progress=False)
    for path in (project / "studies" / "04_hdt" / "tasks").glob("*.json"):
        rec = json.loads(path.read_text())
        for row in rec["rows"]:
            del row["seed"]
        path.write_text(json.dumps(rec))
    with pytest.raises(ValueError, match="Expect the rows to have the column 'seed'"):
        st.write_claims(CHAPTERS, reps=100)


def test_a_study_file_this_code_cannot_read_does_not_stop_loading_another(project):
    """A long run loads its own study again to commit its rows: a file added meanwhile with a
    key newer than the run's code (dm-c6-gpu-v1's ``beside`` stopped dm-c4c6-v2's commits)
    is read for its ``study:`` id alone when checking ``supersedes``."""
    (project / "params" / "04_hdt.v2.study.yml").write_text(yaml.safe_dump(V2))
    newer = {**STUDY, "study": "fake-a", "a_key_from_the_future": 1}
    (project / "params" / "04_hdt.a.study.yml").write_text(yaml.safe_dump(newer))
    assert st.load_study("04_hdt:v2").supersedes == "fake-v1"
    with pytest.raises(ValueError, match="a_key_from_the_future"):
        st.load_study("04_hdt:a")
