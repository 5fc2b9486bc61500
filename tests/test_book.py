"""The book machinery: parameters, profiles, results, paper comparison, the survey data."""

from __future__ import annotations

import dataclasses
import json

import pandas as pd
import pytest

from thesis_lib.book import (
    ChapterResults,
    compare_with_paper,
    config_from_namespace,
    list_chapters,
    load_profile,
    load_reference,
    notebook_parameters,
    project_root,
    reference_tables,
    resolve_chapter,
    validate_parameters,
)
from thesis_lib.chapters.survey import count_values, duplicate_citations, load_survey, split_values


@dataclasses.dataclass
class _Cfg:
    seed: int = 0
    iterations: int = 10

    def __post_init__(self):
        if self.iterations < 1:
            raise ValueError("iterations must be positive")


def test_unknown_parameter_lists_valid_names_and_suggests():
    with pytest.raises(
        ValueError,
        match=r"Unknown parameter 'iteration' for notebook 04_hdt\. "
        r"Did you mean: 'iterations'\? Valid: iterations, seed\.",
    ):
        validate_parameters(["seed", "iteration"], ["seed", "iterations"], "04_hdt")
    validate_parameters([], ["seed"])  # nothing given is fine


def test_config_from_namespace_ignores_kernel_names_modules_and_earlier_configs():
    import math

    ns = {
        "seed": 3,
        "iterations": 5,
        "In": [],
        "_i1": "",
        "math": math,
        "_Cfg": _Cfg,
        "cfg": _Cfg(),
        "config_from_namespace": config_from_namespace,
    }
    cfg = config_from_namespace(_Cfg, ns, "demo")
    assert cfg == _Cfg(seed=3, iterations=5)


def test_config_from_namespace_rejects_injected_unknown_name_and_bad_value():
    with pytest.raises(ValueError, match="Unknown parameter 'sede'.*Did you mean: 'seed'"):
        config_from_namespace(_Cfg, {"seed": 1, "sede": 2}, "demo")
    with pytest.raises(ValueError, match="iterations must be positive"):
        config_from_namespace(_Cfg, {"iterations": 0}, "demo")
    with pytest.raises(TypeError, match="not a dataclass"):
        config_from_namespace(dict, {}, "demo")


def test_reference_tables_are_packaged_and_load_as_printed():
    assert len(reference_tables()) == 13
    t53 = load_reference("Table 5.3")
    assert list(t53.columns) == ["task", "dataset", "data_avg", "bc", "dt", "hdt"]
    assert len(t53) == 31
    assert len(load_reference("table_3_4")) == 111
    with pytest.raises(ValueError, match="No reference table '9.9'. Available: table_3_4"):
        load_reference("9.9")


def test_compare_with_paper_joins_and_explains():
    paper = load_reference("4.2")  # Seen 85.0 / Seen + Unseen / Unseen
    ours = pd.DataFrame(
        {"viewpoints": ["Seen", "Unseen", "Novel"], "accuracy_pct": [80.0, 70.0, 50.0]}
    )
    out = compare_with_paper(
        "4.2",
        ours,
        on=["viewpoints"],
        value="accuracy_pct",
        differs={"data": "MuJoCo scene", "scale": "smoke"},
    )
    assert list(out.columns) == ["viewpoints", "paper", "ours", "difference", "what differs"]
    seen = out.set_index("viewpoints").loc["Seen"]
    expected = float(paper.set_index("viewpoints").loc["Seen", "accuracy_pct"])
    assert seen["paper"] == expected and seen["ours"] == 80.0
    assert seen["difference"] == pytest.approx(80.0 - expected)
    assert seen["what differs"] == "data: MuJoCo scene; scale: smoke"
    notes = out.set_index("viewpoints")["what differs"]
    assert notes["Seen + Unseen"] == "not run"
    assert notes["Novel"].startswith("not in the thesis")
    assert pd.isna(out.set_index("viewpoints").loc["Novel", "paper"])


def test_compare_with_paper_errors_and_filters():
    ours = pd.DataFrame({"viewpoints": ["Seen"], "acc": [1.0]})
    with pytest.raises(ValueError, match=r"Column\(s\) \['acc'\] not in the thesis table"):
        compare_with_paper("4.2", ours, on=["viewpoints"], value="acc")
    with pytest.raises(ValueError, match="Unknown deviation kind 'speed'"):
        compare_with_paper(
            "4.2",
            ours,
            on=["viewpoints"],
            value="acc",
            paper_value="accuracy_pct",
            differs={"speed": "x"},
        )
    t = load_reference("4_3_4_4")
    only43 = compare_with_paper(
        "4_3_4_4",
        t[t.table == 4.3].head(0).assign(x=[]),
        on=["env"],
        value="x",
        paper_value="acc_reward_mean",
        where={"table": 4.3},
    )
    assert (only43["what differs"] == "not run").all()
    assert len(only43) == (t.table == 4.3).sum() == 36


def test_chapter_results_writes_files_and_provenance(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    res = ChapterResults("demo", config=_Cfg(seed=7), seed=7)
    res.table("t", pd.DataFrame({"a": [1, 2]}))
    fig, ax = plt.subplots()
    ax.plot([0, 1])
    res.figure("f", fig)
    res.json("extra", {"k": 1})
    meta = res.finish()
    on_disk = json.loads((tmp_path / "demo" / "run.json").read_text())
    assert on_disk["config"] == {"seed": 7, "iterations": 10} and on_disk["seed"] == 7
    assert on_disk["artifacts"] == ["t.csv", "f.png", "extra.json"] == meta["artifacts"]
    assert len(on_disk["git_commit"]) >= 7 and "numpy" in on_disk["versions"]
    assert on_disk["wall_time_s"] >= 0
    assert pd.read_csv(tmp_path / "demo" / "t.csv")["a"].tolist() == [1, 2]
    with pytest.raises(TypeError, match="must be a pandas DataFrame"):
        res.table("bad", [1, 2])


def test_chapter_results_examples_leave_nothing_in_the_temp_dir(tmp_path, monkeypatch):
    """The ChapterResults example made its results folder with mkdtemp and never removed it:
    one more folder in the system's temp dir per test run."""
    import doctest
    import tempfile

    from thesis_lib.book import results

    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.delenv("THESIS_RESULTS_DIR", raising=False)  # the example sets and removes it
    outcome = doctest.testmod(results, report=False)
    assert outcome.attempted > 0 and outcome.failed == 0
    assert sorted(p.name for p in temp.iterdir()) == []


def test_toc_chapters_have_notebooks_and_profiles_match_defaults():
    root = project_root()
    chapters = list_chapters(root)
    assert "01_background" in chapters and "survey" in chapters
    for chapter in chapters:
        defaults = notebook_parameters(chapter, root)
        smoke = load_profile(chapter, "smoke", root)
        assert smoke == defaults, f"params/{chapter}.smoke.yml must equal the notebook's defaults"
        full = load_profile(chapter, "full", root)
        validate_parameters(full, defaults, chapter)


def test_resolve_chapter_and_profile_errors():
    assert resolve_chapter("01") == "01_background"
    assert resolve_chapter("background") == "01_background"
    assert resolve_chapter("notebooks/survey.ipynb") == "survey"
    with pytest.raises(ValueError, match="'nope' is not a chapter. Chapters: 01_background"):
        resolve_chapter("nope")
    with pytest.raises(ValueError, match="Unknown profile 'huge'"):
        load_profile("survey", "huge")
    with pytest.raises(FileNotFoundError, match="No parameter file"):
        load_profile("survey", "missing.yml")


def test_survey_counts_split_multi_valued_cells():
    df = load_survey()
    assert split_values("Policy Learning, IRL") == ["Policy Learning", "IRL"]
    assert split_values(None) == []
    tech = count_values(df, "technique")
    assert tech["Telesoperation"] == 61 and tech["N/A"] == 21  # kept as printed
    goals = count_values(df, "learned_goal")
    n_split = df["learned_goal"].map(split_values).map(len).sum()
    assert goals.sum() == n_split
    assert count_values(df, "year").sum() == 111
    assert sorted(duplicate_citations(df)["ref"].unique().tolist()) == [141, 142, 194, 208]
    with pytest.raises(ValueError, match="no column 'tech'"):
        count_values(df, "tech")


def test_api_reference_lists_every_package():
    """book/api.md documents each sub-package of thesis_lib (one line each in `api-packages`)."""
    import re

    root = project_root()
    listed = re.findall(r"^\s+(thesis_lib\.\w+)\s*$", (root / "book" / "api.md").read_text(), re.M)
    packages = sorted(
        f"thesis_lib.{p.parent.name}" for p in (root / "src" / "thesis_lib").glob("*/__init__.py")
    )
    missing = sorted(set(packages) - set(listed))
    assert not missing, f"add to the api-packages list in book/api.md: {', '.join(missing)}"
    assert len(listed) == len(set(listed))


def test_a_table_and_a_figure_may_not_share_a_name(tmp_path, monkeypatch):
    # both would be glued as <chapter>/<name>, which the book's strict build rejects
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from thesis_lib.book import ChapterResults

    monkeypatch.setenv("THESIS_RESULTS_DIR", str(tmp_path))
    res = ChapterResults("demo")
    res.table("scores", pd.DataFrame({"x": [1]}))
    res.table("scores", pd.DataFrame({"x": [2]}))  # rewriting one's own table is fine
    fig, _ = plt.subplots()
    with pytest.raises(ValueError, match="'scores' is already a table of demo"):
        res.figure("scores", fig)
    res.figure("scores_plot", fig)


def test_git_commit_is_dirty_for_code_changes_not_for_the_studies_own_files(tmp_path):
    import subprocess

    from thesis_lib.provenance import commit_record, git_commit, git_dirty_paths

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
            cwd=tmp_path,
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()

    assert git_commit(tmp_path) == "unknown"  # not a checkout
    (tmp_path / "studies" / "04_hdt").mkdir(parents=True)
    (tmp_path / "studies" / "04_hdt" / "rows.csv").write_text("a\n1\n")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("init", "-q")
    git("add", ".")
    git("commit", "-q", "-m", "0")
    sha = git("rev-parse", "HEAD")
    assert git_commit(tmp_path) == sha
    (tmp_path / "studies" / "04_hdt" / "rows.csv").write_text("a\n1\n2\n")  # a running study
    (tmp_path / "new.py").write_text("untracked\n")
    assert git_commit(tmp_path) == sha
    (tmp_path / "code.py").write_text("x = 2\n")
    assert git_commit(tmp_path) == f"{sha}-dirty"
    assert git_commit(tmp_path / "studies") == f"{sha}-dirty"  # from a sub-folder too
    # the record names what made it dirty (from the top, whatever the folder), not the study
    assert commit_record(tmp_path / "studies") == {
        "git_commit": f"{sha}-dirty",
        "git_dirty": ["code.py"],
    }
    git("add", "code.py")
    git("commit", "-q", "-m", "1")
    assert commit_record(tmp_path) == {"git_commit": git("rev-parse", "HEAD")}
    assert git_dirty_paths(tmp_path) == []
    # a rename names both files, and a name with a space or an accent comes back as it is
    (tmp_path / "a b é.py").write_text("y = 1\n")
    git("add", "a b é.py")
    git("commit", "-q", "-m", "2")
    git("mv", "code.py", "moved.py")
    (tmp_path / "a b é.py").write_text("y = 2\n")
    assert git_dirty_paths(tmp_path) == sorted(["a b é.py", "code.py", "moved.py"])
