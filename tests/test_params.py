"""One source for parameters: a chapter's Config generates its notebook's ``parameters`` cell
and ``params/<chapter>.smoke.yml``; ``params/<chapter>.full.yml`` lists only what differs."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
import types
from dataclasses import dataclass, field
from pathlib import Path

import nbformat
import pytest
import yaml

from thesis_lib.book.chapter import Chapter
from thesis_lib.book.params import (
    check_chapter,
    check_full_profile,
    config_defaults,
    config_from_namespace,
    field_docs,
    notebook_parameters_cell,
    parameters_source,
    parse_value,
    prune_full_yaml,
    smoke_yaml,
    write_chapter,
)
from thesis_lib.chapters import CHAPTERS


@dataclass
class Config:
    """A chapter's parameters for the tests (``thesis params`` finds it as ``<module>.Config``)."""

    seed: int = 0
    """Seed of every random draw. A second sentence that the cell leaves out."""
    lr: float = 1e-3  # peak learning rate
    name: str = 'say "hi"'
    path: str | None = None
    """Where the data is (``None``: generate it)."""
    flag: bool = False
    sizes: tuple[int, ...] = (8, 16)
    """Widths, with n = 2 layers; papermill must still parse this line."""
    datasets: list[str] = field(
        default_factory=lambda: [f"task{i}/medium-replay-with-a-long-name" for i in range(4)]
    )
    """Data sets (long enough to be one per line)."""
    steps: dict[str, int] = field(default_factory=lambda: {"SAC": 4000, "TD3": 8000})
    note: str = "x"
    """A docstring long enough that the comment cannot stay on the line of its field, so it goes on the line above it."""

    def __post_init__(self) -> None:
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")


EXPECTED_CELL = '''\
seed = 0  # Seed of every random draw.
lr = 0.001  # peak learning rate
name = 'say "hi"'
path = None  # Where the data is (``None``: generate it).
flag = False
sizes = [8, 16]  # Widths, with n: 2 layers; papermill must still parse this line.
datasets = [
    "task0/medium-replay-with-a-long-name",
    "task1/medium-replay-with-a-long-name",
    "task2/medium-replay-with-a-long-name",
    "task3/medium-replay-with-a-long-name",
]  # Data sets (long enough to be one per line).
steps = {"SAC": 4000, "TD3": 8000}
# A docstring long enough that the comment cannot stay on the line of its field, so it goes on the
# line above it.
note = "x"'''


@dataclass
class Other:
    seed: int = 1
    steps: int = 10


def _ruff() -> str | None:
    exe = Path(sys.executable).with_name("ruff")
    return str(exe) if exe.exists() else shutil.which("ruff")


def _assert_ruff_clean(source: str) -> None:
    ruff = _ruff()
    if ruff is None:
        pytest.skip("ruff is not installed")
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [ruff, "format", "--check", "--diff", "--stdin-filename", "cell.py", "-"],
        input=source + "\n",
        capture_output=True,
        text=True,
        cwd=root,  # the project's ruff settings (line length 100)
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _fake_notebook(path: Path, source: str) -> None:
    intro = nbformat.v4.new_markdown_cell("# Demo chapter")
    params = nbformat.v4.new_code_cell(source)
    params.metadata["tags"] = ["parameters"]
    build = nbformat.v4.new_code_cell('cfg = config_from_namespace(Config, globals(), "99_demo")')
    out = nbformat.v4.new_code_cell("print(cfg)")
    out.outputs = [nbformat.v4.new_output("stream", name="stdout", text="Config(...)\n")]
    nb = nbformat.v4.new_notebook(cells=[intro, params, build, out])
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, path)


def test_defaults_and_docs():
    d = config_defaults(Config)
    assert d["sizes"] == [8, 16] and d["lr"] == 0.001 and d["path"] is None
    assert list(d) == [f.name for f in dataclasses.fields(Config)]
    docs = field_docs(Config)
    assert docs["lr"] == "peak learning rate"  # a comment on the field's line
    assert docs["seed"].startswith("Seed of every random draw. A second")
    assert "flag" not in docs


def test_parameters_cell_text():
    src = parameters_source(Config)
    assert src == EXPECTED_CELL
    assert parameters_source(Config) == src  # stable


def test_parameters_cell_is_ruff_clean():
    _assert_ruff_clean(parameters_source(Config))


def test_parameters_cell_round_trips(tmp_path):
    import papermill as pm

    src = parameters_source(Config)
    ns: dict = {}
    exec(src, ns)
    cfg = config_from_namespace(Config, ns, "99_demo")
    assert dataclasses.asdict(cfg) == config_defaults(Config)  # (a tuple comes back as a list)
    # papermill reads every parameter and its value (the help comments do not confuse it)
    nb = tmp_path / "nb.ipynb"
    _fake_notebook(nb, src)
    info = pm.inspect_notebook(str(nb))
    assert {k: parse_value(v["default"]) for k, v in info.items()} == config_defaults(Config)
    assert info["seed"]["help"] == "Seed of every random draw."


def test_smoke_yaml():
    text = smoke_yaml(Config)
    assert text.startswith(f"# Generated from {__name__}.Config by `thesis params --write`")
    assert yaml.safe_load(text) == config_defaults(Config)
    assert list(yaml.safe_load(text)) == list(config_defaults(Config))  # field order
    assert smoke_yaml(Config) == text


def test_bad_configs():
    @dataclass
    class NoDefault:
        seed: int

    @dataclass
    class Odd:
        where: object = dataclasses.field(default_factory=object)

    with pytest.raises(TypeError, match="every field a default.*seed"):
        parameters_source(NoDefault)
    with pytest.raises(TypeError, match=r"Odd.where: default .*object"):
        smoke_yaml(Odd)
    with pytest.raises(TypeError, match="not a dataclass"):
        config_defaults(dict)


def test_full_profile_lists_only_differences():
    assert check_full_profile(Config, {"seed": 3, "lr": 1e-4}) == []
    problems = check_full_profile(
        Config, {"seed": 0, "sizes": (8, 16), "lrr": 0.1, "steps": {"SAC": 1}}, "x.full.yml"
    )
    assert problems == [
        "x.full.yml: 'lrr' is not a parameter of Config (did you mean 'lr'?)",
        "x.full.yml: 'seed' has the smoke value 0; list only what differs from smoke",
        "x.full.yml: 'sizes' has the smoke value (8, 16); list only what differs from smoke",
    ]
    (bad,) = check_full_profile(Config, {"seed": -1})
    assert "Config rejects these values: seed must be >= 0" in bad


def test_prune_full_yaml_keeps_the_header():
    text = "# The thesis's scale.\n# Two lines.\n\nseed: 0\nlr: 0.0001\nsizes: [8, 16]\n"
    pruned = prune_full_yaml(text, config_defaults(Config))
    assert pruned == "# The thesis's scale.\n# Two lines.\nlr: 0.0001\n"
    assert prune_full_yaml(pruned, config_defaults(Config)) == pruned
    assert prune_full_yaml("seed: 0\n", config_defaults(Config)) == ""


def _project(root: Path, source: str = "seed = 5") -> None:
    _fake_notebook(root / "notebooks" / "99_demo.ipynb", source)
    (root / "params").mkdir()
    (root / "params" / "99_demo.smoke.yml").write_text("seed: 5\n")
    (root / "params" / "99_demo.full.yml").write_text("# big\nseed: 0\nlr: 0.01\n")
    (root / "_toc.yml").write_text("format: jb-book\nroot: intro\nchapters:\n")
    with (root / "_toc.yml").open("a") as f:
        f.write("- file: book/generated/99_demo\n")


def test_check_and_write_a_chapter(tmp_path):
    _project(tmp_path)
    problems = check_chapter("99_demo", Config, tmp_path)
    assert len(problems) == 3
    assert "notebooks/99_demo.ipynb: the parameters cell differs from Config" in problems[0]
    assert "params/99_demo.smoke.yml differs from Config" in problems[1]
    assert "'seed' has the smoke value 0" in problems[2]

    before = nbformat.read(tmp_path / "notebooks" / "99_demo.ipynb", as_version=4)
    changed = write_chapter("99_demo", Config, tmp_path)
    assert [p.name for p in changed] == ["99_demo.ipynb", "99_demo.smoke.yml", "99_demo.full.yml"]
    assert check_chapter("99_demo", Config, tmp_path) == []
    assert write_chapter("99_demo", Config, tmp_path) == []  # nothing left to change

    nb = nbformat.read(tmp_path / "notebooks" / "99_demo.ipynb", as_version=4)
    assert notebook_parameters_cell(tmp_path / "notebooks" / "99_demo.ipynb") == EXPECTED_CELL
    # only the parameters cell changed: the other cells and their outputs are kept
    assert [c.source for c in nb.cells[2:]] == [c.source for c in before.cells[2:]]
    assert nb.cells[3].outputs == before.cells[3].outputs
    assert nb.cells[1].metadata["tags"] == ["parameters"]
    assert (tmp_path / "params" / "99_demo.full.yml").read_text() == "# big\nlr: 0.01\n"

    # another Config: the files no longer match
    assert len(check_chapter("99_demo", Other, tmp_path)) >= 2


def test_a_notebook_needs_one_parameters_cell(tmp_path):
    path = tmp_path / "nb.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x = 1")]), path)
    with pytest.raises(ValueError, match="exactly one cell tagged 'parameters', has 0"):
        notebook_parameters_cell(path)


def test_thesis_params_command(tmp_path, monkeypatch, capsys):
    from thesis_lib.cli import main

    _project(tmp_path)
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    this = sys.modules[__name__]
    monkeypatch.setitem(CHAPTERS, "99_demo", Chapter("99_demo", Path(__file__), lambda: this))
    assert main(["params", "--check", "99_demo"]) == 1
    err = capsys.readouterr().err
    assert "99_demo: notebooks/99_demo.ipynb: the parameters cell differs" in err
    assert main(["params", "99_demo"]) == 0  # prints the cell, writes nothing
    assert EXPECTED_CELL in capsys.readouterr().out
    assert notebook_parameters_cell(tmp_path / "notebooks" / "99_demo.ipynb") == "seed = 5"
    assert main(["params", "--write"]) == 0  # every chapter of _toc.yml
    assert "99_demo: wrote notebooks/99_demo.ipynb" in capsys.readouterr().out
    assert main(["params", "--check"]) == 0
    nothing = types.SimpleNamespace()  # a chapter package without a Config
    monkeypatch.setitem(CHAPTERS, "99_demo", Chapter("99_demo", Path(__file__), lambda: nothing))
    assert main(["params", "--check"]) == 1
    assert "99_demo: its package has no dataclass Config" in capsys.readouterr().err


def _chapter_config_or_skip(chapter: str) -> type:
    return CHAPTERS[chapter].Config


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_chapter_configs_generate_valid_cells(chapter):
    cls = _chapter_config_or_skip(chapter)
    src = parameters_source(cls)
    ns: dict = {}
    exec(src, ns)
    cfg = config_from_namespace(cls, ns, chapter)
    assert json.loads(json.dumps(dataclasses.asdict(cfg))) == config_defaults(cls)
    _assert_ruff_clean(src)


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_chapter_notebook_and_params_match_the_config(chapter):
    """`thesis params --write` has been run: the notebook's parameters cell, the smoke profile
    and the full profile (only differences) agree with the chapter's Config."""
    from thesis_lib.book import project_root

    cls = _chapter_config_or_skip(chapter)
    assert check_chapter(chapter, cls, project_root()) == []


def test_existing_config_generates_a_valid_cell():
    """A real chapter Config round-trips through its generated cell."""
    from thesis_lib.chapters import background as bg

    src = parameters_source(bg.Config)
    ns: dict = {}
    exec(src, ns)
    assert config_from_namespace(bg.Config, ns) == bg.Config()
    _assert_ruff_clean(src)


def test_spec_from_takes_same_named_fields_then_overrides():
    """The one way a chapter's flat Config becomes a method's spec (``spec_from``)."""
    from thesis_lib.book.params import spec_from
    from thesis_lib.chapters.ur3 import Config as Ur3Config
    from thesis_lib.seq.registry import ArchSpec
    from thesis_lib.seq.runner import TrainSpec

    cfg = Ur3Config(d_model=48, lr=2e-3, batch_size=7)
    arch = spec_from(cfg, ArchSpec, max_timestep=300)
    assert (arch.d_model, arch.max_timestep, arch.n_heads) == (48, 300, cfg.n_heads)
    assert arch.bc_hidden_dim == ArchSpec().bc_hidden_dim  # not a Config field: the default
    train = spec_from(cfg, TrainSpec, seed=9)
    assert (train.lr, train.batch_size, train.seed) == (2e-3, 7, 9)
    assert cfg.arch() == spec_from(cfg, ArchSpec, max_timestep=max(256, cfg.max_eval_steps + 1))
    with pytest.raises(TypeError, match="TrainSpec has no field 'lrr'"):
        spec_from(cfg, TrainSpec, lrr=1.0)
