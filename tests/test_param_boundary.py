"""One parameter boundary (issue #37): every chapter parameter is checked once, against the type
hints of its chapter's ``Config``, before a kernel starts (``thesis run -p``/``-f``) or before the
``Config`` is built (a notebook's ``config_from_namespace``, a study file)."""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from typing import Literal, get_args

import nbformat
import pytest

from thesis_lib.book.params import (
    check_parameters,
    check_value,
    config_from_namespace,
    config_hints,
)
from thesis_lib.chapters import CHAPTERS


@dataclass
class Demo:
    seed: int = 0
    lr: float = 1e-3
    flag: bool = False
    algos: list[str] = field(default_factory=lambda: ["SAC"])
    seeds: list[int] = field(default_factory=lambda: [0])
    size: Literal["smoke", "full"] = "smoke"
    root: str | None = None
    steps: int | dict[str, int] = 10
    genres: list[str] | None = None


@pytest.fixture
def no_kernel(monkeypatch):
    """``papermill.execute_notebook`` replaced: it copies the notebook and records the
    parameters it was given, so ``thesis run`` is tested up to the kernel without one."""
    import papermill as pm

    calls: list[dict] = []

    def execute(inp, out, parameters=None, **kwargs):
        calls.append(dict(parameters or {}))
        shutil.copy(inp, out)

    monkeypatch.setattr(pm, "execute_notebook", execute)
    return calls


def _thesis_run(capsys, *argv: str) -> tuple[int, str]:
    from thesis_lib.cli import main

    rc = main(["run", *argv])
    return rc, capsys.readouterr().err.strip()


# --- the rows --------------------------------------------------------------------------


def test_rl_timesteps_shorter_than_an_episode_is_a_clear_error():
    """``thesis run 01_background -p rl_timesteps 100``: Pendulum-v1's episodes are 200 steps,
    so no episode ends, the curves are empty and ``summarize_rl`` (then ``summarise_rl``) raised ``KeyError: 'algo'``."""
    from thesis_lib.chapters import background as bg

    cfg = bg.Config(rl_algos=["DDPG"], rl_timesteps=100)
    with pytest.raises(ValueError, match="rl_timesteps"):
        bg.summarize_rl(bg.run_rl_curves(cfg))


@pytest.mark.parametrize(
    ("chapter", "name", "value"),
    [
        ("01_background", "rl_algos", "SAC"),
        ("06_mdlt", "variants", "transformer"),
        ("03_defender", "algos", "SAC"),
    ],
)
def test_a_string_for_a_list_field_is_one_item_not_its_characters(chapter, name, value):
    """``-p rl_algos PPO`` gave "Unknown algorithm 'P'": the string was iterated."""
    cls = CHAPTERS[chapter].Config
    cfg = config_from_namespace(cls, {name: value}, chapter)
    assert getattr(cfg, name) == [value]


def test_an_unknown_algorithm_given_alone_is_named_whole():
    from thesis_lib.chapters import background as bg

    with pytest.raises(ValueError, match="Unknown algorithm 'PPO' in rl_algos"):
        config_from_namespace(bg.Config, {"rl_algos": "PPO"}, "01_background")


def test_thesis_run_wraps_a_string_for_a_list_field(no_kernel, capsys, tmp_path):
    rc, err = _thesis_run(
        capsys, "01_background", "-p", "rl_algos", "SAC", "-o", str(tmp_path / "o.ipynb"), "-q"
    )
    assert (rc, err) == (0, "")
    assert no_kernel[0]["rl_algos"] == ["SAC"]
    rc, _ = _thesis_run(
        capsys, "01_background", "-p", "rl_algos", "[SAC, TD3]", "-o", str(tmp_path / "o.ipynb")
    )
    assert rc == 0 and no_kernel[1]["rl_algos"] == ["SAC", "TD3"]  # YAML-looking: parsed


@pytest.mark.parametrize(
    ("chapter", "name", "text", "message"),
    [
        ("04_hdt", "iterations", "abc", "Expect `iterations` to be an int, actually: 'abc'"),
        ("04_hdt", "seed", "1.5", "Expect `seed` to be an int, actually: 1.5"),
        ("04_hdt", "seed", "true", "Expect `seed` to be an int, actually: True"),
        ("04_hdt", "iterations", "2.5", "Expect `iterations` to be an int, actually: 2.5"),
        ("06_mdlt", "iterations", "2.5", "Expect `iterations` to be an int, actually: 2.5"),
        ("07_ur3_deployment", "iterations", "2.5", "Expect `iterations` to be an int"),
        ("04_hdt", "dataset_size", "big", "Expect `dataset_size` to be one of 'smoke', 'full'"),
        ("04_hdt", "paper_compat", "1", "Expect `paper_compat` to be true or false, actually: 1"),
    ],
)
def test_thesis_run_refuses_a_bad_value_before_the_kernel(
    no_kernel, capsys, tmp_path, chapter, name, text, message
):
    rc, err = _thesis_run(capsys, chapter, "-p", name, text, "-o", str(tmp_path / "o.ipynb"))
    assert rc == 1 and no_kernel == []  # papermill never started
    assert err.startswith(f"thesis run: {message}") and "\n" not in err  # one line
    assert err.endswith(f"(from -p {name} {text})")


def test_a_whole_float_is_an_int(no_kernel, capsys, tmp_path):
    rc, _ = _thesis_run(capsys, "04_hdt", "-p", "iterations", "2.0", "-o", str(tmp_path / "o"))
    assert rc == 0 and no_kernel[0]["iterations"] == 2
    assert type(no_kernel[0]["iterations"]) is int


def test_a_broken_parameter_file_is_one_line(no_kernel, capsys, tmp_path):
    broken = tmp_path / "broken.yml"
    broken.write_text("seed: 1\nalgos: [SAC, TD3\niterations: 3\n")
    rc, err = _thesis_run(capsys, "04_hdt", "-f", str(broken))
    assert rc == 1 and no_kernel == []
    assert err.startswith(f"thesis run: {broken}, line 3: invalid YAML (")
    assert "\n" not in err


def test_a_bad_value_in_a_parameter_file_names_the_file(no_kernel, capsys, tmp_path):
    bad = tmp_path / "bad.yml"
    bad.write_text("iterations: 2.5\n")
    rc, err = _thesis_run(capsys, "04_hdt", "-f", str(bad))
    assert rc == 1 and no_kernel == []
    assert err == f"thesis run: Expect `iterations` to be an int, actually: 2.5 (in {bad})"


def test_the_notebook_refuses_what_papermill_injects():
    """Plain papermill injects ``seed = 1.5`` (and passes a list as text): the notebook's
    ``config_from_namespace`` call is the same check."""
    from thesis_lib.chapters import hdt

    with pytest.raises(
        ValueError, match=r"^Expect `seed` to be an int, actually: 1\.5 \(in 04_hdt\)$"
    ):
        config_from_namespace(hdt.Config, {"seed": 1.5}, "04_hdt")
    cfg = config_from_namespace(hdt.Config, {"methods": "[DT, HDT]", "iterations": 3.0}, "04_hdt")
    assert cfg.methods == ["DT", "HDT"] and cfg.iterations == 3


def test_a_study_file_is_checked_the_same_way():
    from thesis_lib.book.study import Study, study_config

    study = Study("demo-v1", "04_hdt", {"iterations": 2.5}, "score", [])
    with pytest.raises(ValueError, match=r"Expect `iterations` to be an int, actually: 2\.5"):
        study_config(study, CHAPTERS["04_hdt"])


# --- the check itself --------------------------------------------------------------------------


def test_check_value_accepts_and_converts():
    assert check_parameters(
        config_hints(Demo),
        {
            "seed": 3.0,
            "lr": 1,
            "flag": True,
            "algos": ("SAC", "TD3"),
            "seeds": 4,
            "size": "full",
            "root": None,
            "steps": {"SAC": 5.0},
            "genres": "mHO",
        },
    ) == {
        "seed": 3,
        "lr": 1,
        "flag": True,
        "algos": ("SAC", "TD3"),
        "seeds": [4],
        "size": "full",
        "root": None,
        "steps": {"SAC": 5},
        "genres": ["mHO"],
    }
    assert check_value("genres", None, list[str] | None) is None
    assert check_value("sizes", [8, 16], tuple[int, ...]) == [8, 16]


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("seed", False, "an int"),
        ("lr", "fast", "a number"),
        ("lr", True, "a number"),
        ("flag", "yes please", "true or false"),
        ("flag", 0, "true or false"),
        ("algos", {"SAC": 1}, "a list of strings"),
        ("algos", ["SAC", 3], "a list of strings"),
        ("seeds", [0, 1.5], "a list of ints"),
        ("size", "huge", "one of 'smoke', 'full'"),
        ("root", 3, "a string or None"),
        ("steps", "many", "an int or a mapping of strings to ints"),
        ("genres", 7, "a list of strings or None"),
    ],
)
def test_check_value_refuses_with_name_value_and_expectation(name, value, expected):
    with pytest.raises(ValueError) as err:
        check_parameters(config_hints(Demo), {name: value}, "in demo.yml")
    assert str(err.value) == f"Expect `{name}` to be {expected}, actually: {value!r} (in demo.yml)"


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_chapter_hints_read_without_import_match_the_config(chapter):
    cls = CHAPTERS[chapter].Config
    assert list(CHAPTERS[chapter].hints().items()) == list(config_hints(cls).items())


def _refuse_import():
    raise AssertionError("hints() imported the chapter")


def test_hints_follow_a_thesis_lib_base_without_importing_and_fall_back_otherwise(tmp_path):
    """A ``Config`` subclassing ``SeqTraining`` is read from the two files, the base's fields
    first as ``dataclasses.fields`` has them; a base from elsewhere takes the import."""
    from pathlib import Path

    from thesis_lib.book.chapter import Chapter

    ours = tmp_path / "ours.py"
    ours.write_text(
        "from dataclasses import dataclass\n"
        "from thesis_lib.chapters.seq_config import SeqTraining\n\n"
        "@dataclass\nclass Config(SeqTraining):\n    seed: int = 0\n"
    )
    hints = Chapter("99_demo", Path(ours), _refuse_import).hints()
    assert list(hints) == ["init", "sampling", "device", "precision", "kernels", "seed"]
    assert get_args(hints["kernels"]) == ("torch", "fast", "fast+readout") and hints["seed"] is int

    other = tmp_path / "other.py"
    other.write_text(
        "from dataclasses import dataclass\nfrom somewhere import Base\n\n"
        "@dataclass\nclass Config(Base):\n    seed: int = 0\n"
    )

    @dataclass
    class Base:
        device: str = "cpu"

    @dataclass
    class Config(Base):
        seed: int = 0

    module = type(shutil)("demo")
    module.Config = Config  # type: ignore[attr-defined]
    assert Chapter("99_demo", Path(other), lambda: module).hints() == {"device": str, "seed": int}


@pytest.mark.parametrize("chapter", sorted(c for c in CHAPTERS if "init" in CHAPTERS[c].hints()))
def test_a_chapters_init_takes_every_scheme_the_models_know(chapter):
    """``thesis run -p init d3rlpy`` reaches the models: the hint lists :data:`INIT_SCHEMES`."""
    from thesis_lib.seq.models import INIT_SCHEMES

    assert get_args(CHAPTERS[chapter].hints()["init"]) == INIT_SCHEMES
    assert check_value("init", "d3rlpy", CHAPTERS[chapter].hints()["init"]) == "d3rlpy"
    with pytest.raises(ValueError, match="init"):
        check_value("init", "xavier", CHAPTERS[chapter].hints()["init"])


@pytest.mark.slow
def test_papermill_runs_the_check_in_the_kernel(tmp_path):
    """A tiny chapter notebook run by papermill, as ``papermill nb.ipynb out.ipynb -p seed 1.5``."""
    import papermill as pm

    (tmp_path / "tiny_cfg.py").write_text(
        "from dataclasses import dataclass, field\n\n\n@dataclass\nclass Config:\n"
        "    seed: int = 0\n    algos: list[str] = field(default_factory=lambda: ['SAC'])\n"
    )
    params = nbformat.v4.new_code_cell("seed = 0\nalgos = ['SAC']")
    params.metadata["tags"] = ["parameters"]
    build = nbformat.v4.new_code_cell(
        "import sys\nsys.path.insert(0, '.')\nfrom tiny_cfg import Config\n"
        "from thesis_lib.book import config_from_namespace\n"
        "cfg = config_from_namespace(Config, globals(), 'tiny')\nassert cfg.algos == ['TD3'], cfg"
    )
    nb = nbformat.v4.new_notebook(cells=[params, build])
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, tmp_path / "nb.ipynb")
    run = dict(kernel_name="python3", cwd=str(tmp_path), progress_bar=False)
    pm.execute_notebook(tmp_path / "nb.ipynb", tmp_path / "ok.ipynb", {"algos": "TD3"}, **run)
    with pytest.raises(pm.PapermillExecutionError, match="Expect `seed` to be an int"):
        pm.execute_notebook(tmp_path / "nb.ipynb", tmp_path / "bad.ipynb", {"seed": 1.5}, **run)


def test_thesis_run_refuses_before_importing_torch():
    """The refusal comes at once: ``thesis run`` imports no sub-package's CLI (the chapters', MDLT's
    and the data's import torch and scipy, seconds) and reads the chapter's hints without it,
    its base's (``SeqTraining``: ``kernels``) from that base's file."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from thesis_lib.cli import main\n"
        "rc = main(['run', '04_hdt', '-p', 'iterations', 'abc'])\n"
        "rc2 = main(['run', '07_ur3_deployment', '-p', 'kernels', 'slow'])\n"
        "print(rc, rc2, 'torch' in sys.modules, 'scipy' in sys.modules,\n"
        "      'thesis_lib.chapters.hdt' in sys.modules)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.split() == ["1", "1", "False", "False", "False"]
    assert "Expect `iterations` to be an int" in proc.stderr
    assert "Expect `kernels` to be one of 'torch', 'fast'" in proc.stderr


def test_the_lazy_subcommands_help_is_the_registered_help():
    """``thesis --help`` lists the sub-packages' commands from ``SUBCOMMANDS`` without importing
    them; each line must be the one the sub-package registers."""
    import argparse

    from thesis_lib.cli import SUBCOMMANDS, build_parser

    full = build_parser()  # every sub-package imported and registered
    lazy = build_parser("run")  # stand-ins only
    for parser in (full, lazy):
        actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        helps = {c.dest: c.help for c in actions[0]._choices_actions}
        for name, (_, text) in SUBCOMMANDS.items():
            assert helps[name] == text, name
    args = build_parser("claims").parse_args(["claims", "--reps", "10"])
    assert args.reps == 10  # the command asked for is the real one
