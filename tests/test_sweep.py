"""thesis_lib.sweep: task keys, the on-disk store, resume, force, executors (in-process, joblib,
Ray), failures and damaged results."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from thesis_lib.sweep import (
    GridFailed,
    Task,
    TaskFailed,
    TaskStore,
    config_hash,
    execute,
    note_resumed_cpu,
    resumed_cpu_s,
    run_tasks,
    scratch_of,
    task_scratch,
)

HERE = Path(__file__).resolve().parent


def square(config: dict) -> list[dict]:
    """A toy task: two rows per config; appends one line to ``config['log']`` per call."""
    if config.get("log"):
        with open(config["log"], "a") as f:
            f.write(f"{config['x']}\n")
    if config["x"] == config.get("fail_at"):
        raise ValueError(f"x={config['x']} is cursed")
    return [
        {"x": config["x"], "seed": config.get("seed", 0), "y": config["x"] ** 2},
        {"x": config["x"], "seed": config.get("seed", 0), "y": -config["x"]},
    ]


def die(config: dict) -> list[dict]:
    """A task whose worker process dies (as one killed for memory)."""
    if config["x"] == config.get("die_at"):
        import signal

        os.kill(os.getpid(), signal.SIGKILL)
    return square(config)


def resumable(config: dict) -> list[dict]:
    """A task that keeps a count of its attempts in its scratch folder and fails until the
    count reaches ``config['succeed_at']``, as a training run that is cut off and resumes."""
    scratch = task_scratch()
    if scratch is None:
        return [{"x": config["x"], "attempts": 0, "scratch": ""}]
    counter = scratch / "attempts.txt"
    n = (int(counter.read_text()) if counter.exists() else 0) + 1
    counter.write_text(str(n))
    if n < config["succeed_at"]:
        raise RuntimeError(f"cut off at attempt {n}")
    return [{"x": config["x"], "attempts": n, "scratch": str(scratch)}]


def resumed_run(config: dict) -> list[dict]:
    """A task that resumes work whose cut-off parts spent ``config['before']`` CPU seconds (as a
    training run resumed from its checkpoint tells it), and reports what it was told back."""
    for seconds in config["before"]:
        note_resumed_cpu(seconds)
    return [{"x": config["x"], "told": resumed_cpu_s()}]


def frame_task(config: dict) -> pd.DataFrame:
    return pd.DataFrame({"x": [config["x"]], "half": [config["x"] / 2]})


def calls(log: Path) -> list[int]:
    return [int(v) for v in log.read_text().split()] if log.exists() else []


def grid(log: Path | None = None, n: int = 5, **extra) -> list[Task]:
    return [
        Task(square, {"x": x, "seed": 0, "log": str(log) if log else None, **extra})
        for x in range(n)
    ]


def test_keys_are_stable_and_change_with_the_config():
    t = Task(square, {"x": 1, "seed": 0})
    # the same config in another key order, and a fresh Task, give the same key
    assert Task(square, {"seed": 0, "x": 1}).key == t.key
    assert len(t.key) == 16 and int(t.key, 16) >= 0
    # a fixed value: the key of a config must not drift between versions (stored results)
    assert config_hash({"a": 1, "b": [1, 2]}) == config_hash({"b": (1, 2), "a": 1})
    assert config_hash({"a": 1}) == "015abd7f5cc57a2d"
    # any change of the config, or another function, changes the key
    assert Task(square, {"x": 2, "seed": 0}).key != t.key
    assert Task(square, {"x": 1, "seed": 1}).key != t.key
    assert Task(square, {"x": 1, "seed": 0, "extra": None}).key != t.key
    assert Task(frame_task, {"x": 1, "seed": 0}).key != t.key


def test_task_function_must_be_module_level():
    with pytest.raises(ValueError, match="module-level"):
        _ = Task(lambda c: [], {"x": 1}).key


def test_execute_record_and_rows(tmp_path):
    rec = execute(Task(frame_task, {"x": 3}))
    assert rec["rows"] == [{"x": 3, "half": 1.5}]
    assert rec["config"] == {"x": 3}
    assert rec["fn"] == f"{__name__}:frame_task"


def test_run_tasks_stores_every_task_with_provenance(tmp_path):
    df = run_tasks(grid(), store=tmp_path, progress=False)
    assert list(df.columns) == ["x", "seed", "y", "task_key"]
    assert df["x"].tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert df["y"].tolist() == [0, 0, 1, -1, 4, -2, 9, -3, 16, -4]
    store = TaskStore(tmp_path)
    assert store.keys() == sorted(t.key for t in grid())
    rec = store.read(grid()[2].key)
    assert rec["config"]["x"] == 2 and len(rec["rows"]) == 2
    assert rec["git_commit"]  # a sha (maybe -dirty) or "unknown" outside a checkout
    assert rec["versions"]["pandas"] == pd.__version__
    assert rec["stored_utc"].endswith("+00:00")
    assert not list(tmp_path.glob("*.tmp"))


def test_resume_after_an_interruption_runs_only_the_rest(tmp_path):
    log = tmp_path / "calls.txt"
    store = tmp_path / "tasks"
    with pytest.raises(TaskFailed) as info:
        run_tasks(grid(log, fail_at=3), store=store, progress=False)
    # the message names the task's config; the original error is the cause
    msg = str(info.value)
    assert '"fail_at":3' in msg and '"x":3' in msg and "cursed" in msg
    assert isinstance(info.value.__cause__, ValueError)
    assert isinstance(info.value, ValueError)  # `except ValueError` still catches it
    assert type(info.value).__name__ == "TaskFailed[ValueError]"
    assert calls(log) == [0, 1, 2, 3]
    assert len(TaskStore(store).keys()) == 3  # the three finished tasks stayed stored

    # the rerun (the failure fixed: the same grid without the cursed value) has other keys,
    # so use a grid whose first three tasks are the stored ones
    log.unlink()
    fixed = grid(log, fail_at=3)[:3] + grid(log, fail_at=99)[3:]
    df = run_tasks(fixed, store=store, progress=False)
    assert calls(log) == [3, 4]  # only the missing tasks ran
    assert df["x"].drop_duplicates().tolist() == [0, 1, 2, 3, 4]
    # a third run computes nothing
    log.unlink()
    again = run_tasks(fixed, store=store, progress=False)
    assert calls(log) == []
    pd.testing.assert_frame_equal(again, df)


def slow_square(config: dict) -> list[dict]:
    """``square``, but each call waits ``config['wait']`` seconds (for the Ctrl-C test)."""
    import time

    time.sleep(config["wait"])
    return square(config)


INTERRUPTED_RUN = """
import signal
import sys
from test_sweep import Task, run_tasks, slow_square
# Ctrl-C must raise KeyboardInterrupt even where the test runner was started in the background
# of a non-interactive shell (nohup ... &), which starts its children with SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)
tasks = [Task(slow_square, {"x": x, "wait": 0.2, "log": sys.argv[2]}) for x in range(8)]
run_tasks(tasks, store=sys.argv[1], executor=sys.argv[3], n_jobs=2, progress=False)
"""


@pytest.mark.parametrize("executor", ["inprocess", "local"])
def test_ctrl_c_then_rerun_finishes_only_the_missing_tasks(tmp_path, executor):
    import signal
    import subprocess
    import sys
    import time

    store, log = tmp_path / "tasks", tmp_path / "calls.txt"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), *sys.path])}
    cmd = [sys.executable, "-c", INTERRUPTED_RUN, str(store), str(log), executor]
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    try:
        while len(TaskStore(store).keys()) < 3:  # wait for three finished tasks, then Ctrl-C
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode != 0 and "KeyboardInterrupt" in err
    stored = TaskStore(store).keys()
    assert 3 <= len(stored) < 8
    assert not list(store.glob("*.tmp"))
    log.unlink()
    rerun = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert len(calls(log)) == 8 - len(stored)  # only the missing tasks ran
    assert len(TaskStore(store).keys()) == 8


@pytest.mark.parametrize("executor", ["inprocess", "local"])
def test_a_task_finds_its_scratch_folder_again_after_it_was_cut_off(tmp_path, executor):
    """task_scratch(): <store>/partial/<key>, kept when the task fails (so the rerun resumes
    from what it left there), removed once its record is stored; None without a store."""
    store = tmp_path / "tasks"
    tasks = [Task(resumable, {"x": x, "succeed_at": 2}) for x in range(2)]
    kw = dict(store=store, executor=executor, n_jobs=2, progress=False, keep_going=True)
    with pytest.raises(GridFailed):
        run_tasks(tasks, **kw)
    for t in tasks:
        assert (scratch_of(store, t.key) / "attempts.txt").read_text() == "1"
    assert not TaskStore(store).keys()
    with pytest.raises(GridFailed):  # force: from the start, the first attempt's state cleared
        run_tasks(tasks, **kw, force=True)
    assert (scratch_of(store, tasks[0].key) / "attempts.txt").read_text() == "1"
    rows = run_tasks(tasks, **kw)
    assert list(rows["attempts"]) == [2, 2]  # each saw its own first attempt's state
    assert [Path(p).name for p in rows["scratch"]] == [t.key for t in tasks]
    assert not any(scratch_of(store, t.key).exists() for t in tasks)  # stored: removed
    assert TaskStore(store).keys() == sorted(t.key for t in tasks)
    free = run_tasks([Task(resumable, {"x": 9, "succeed_at": 2})], progress=False)
    assert free["attempts"].tolist() == [0]  # no store: no scratch
    assert task_scratch() is None


@pytest.mark.parametrize("executor", ["inprocess", "local"])
def test_a_resumed_task_costs_the_cpu_seconds_of_its_cut_off_parts_too(tmp_path, executor):
    """note_resumed_cpu(): a task's record counts the CPU seconds of the parts cut off before
    (cpu_s, and apart as resumed_cpu_s), and the task reads them back (resumed_cpu_s()); a task
    that started fresh records only its own; outside a task the note goes nowhere."""
    tasks = [
        Task(resumed_run, {"x": 0, "before": [600.0, 400.5]}),
        Task(resumed_run, {"x": 1, "before": []}),
    ]
    rows = run_tasks(tasks, store=tmp_path, executor=executor, n_jobs=2, progress=False)
    assert rows.set_index("x")["told"].to_dict() == {0: 1000.5, 1: 0.0}
    resumed, fresh = (TaskStore(tmp_path).read(t.key) for t in tasks)
    assert resumed["resumed_cpu_s"] == 1000.5 and 1000.5 <= resumed["cpu_s"] < 1100
    assert "resumed_cpu_s" not in fresh and fresh["cpu_s"] < 100
    note_resumed_cpu(5.0)  # outside a task
    assert resumed_cpu_s() == 0.0
    assert execute(tasks[1])["cpu_s"] < 100  # nothing noted outside leaks into the next task


def test_force_recomputes(tmp_path, monkeypatch):
    log = tmp_path / "calls.txt"
    run_tasks(grid(log, n=3), store=tmp_path / "s", progress=False)
    run_tasks(grid(log, n=3), store=tmp_path / "s", progress=False, force=True)
    assert calls(log) == [0, 1, 2, 0, 1, 2]
    monkeypatch.setenv("THESIS_SWEEP_FORCE", "1")  # what `thesis run --force` sets
    run_tasks(grid(log, n=3), store=tmp_path / "s", progress=False)
    assert calls(log) == [0, 1, 2, 0, 1, 2, 0, 1, 2]


def test_one_progress_bar_counts_stored_tasks_as_done(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    run_tasks(grid(n=3), store=tmp_path, progress=False)
    capsys.readouterr()
    run_tasks(grid(n=5), store=tmp_path, desc="Table 9.9", progress=True)
    err = capsys.readouterr().err
    assert "Table 9.9" in err and "3/5" in err and "5/5" in err
    assert "1/5" not in err  # starts at the 3 stored tasks
    monkeypatch.setenv("TQDM_DISABLE", "1")  # what `thesis run` sets in a chapter's kernel
    run_tasks(grid(n=6), store=tmp_path, desc="Table 9.9")
    assert "Table 9.9" not in capsys.readouterr().err


def test_no_store_keeps_nothing(tmp_path):
    log = tmp_path / "calls.txt"
    a = run_tasks(grid(log, n=2), progress=False)
    b = run_tasks(grid(log, n=2), progress=False)
    assert calls(log) == [0, 1, 0, 1]
    pd.testing.assert_frame_equal(a, b)


def test_inprocess_and_local_executors_give_the_same_rows(tmp_path):
    tasks = grid(n=6) + [Task(frame_task, {"x": x}) for x in (1, 2)]
    a = run_tasks(tasks, store=tmp_path / "a", executor="inprocess", progress=False)
    b = run_tasks(tasks, store=tmp_path / "b", executor="local", n_jobs=2, progress=False)
    pd.testing.assert_frame_equal(a, b)
    assert a["task_key"].drop_duplicates().tolist() == [t.key for t in tasks]  # task order


def test_local_executor_failure_names_the_config_and_keeps_finished_tasks(tmp_path):
    tasks = grid(n=4, fail_at=0)  # the first task fails; the others may or may not finish
    with pytest.raises(TaskFailed, match=r'"x":0.*cursed') as info:
        run_tasks(tasks, store=tmp_path, executor="local", n_jobs=2, progress=False)
    assert "Traceback of the task" in str(info.value)
    assert isinstance(info.value, ValueError)  # the worker's error type comes back
    store = TaskStore(tmp_path)
    assert tasks[0].key not in store.keys()
    for key in store.keys():  # whatever finished first is stored and readable
        assert len(store.read(key)["rows"]) == 2


@pytest.mark.parametrize("executor", ["inprocess", "local"])
def test_a_failure_keeps_its_traceback_until_the_task_succeeds(tmp_path, executor):
    tasks = grid(n=3, fail_at=1)
    with pytest.raises(TaskFailed, match="cursed"):
        run_tasks(tasks, store=tmp_path, executor=executor, n_jobs=2, progress=False)
    store = TaskStore(tmp_path)
    assert store.failures() == [tasks[1].key]
    text = store.failure_path(tasks[1].key).read_text()
    assert '"x":1' in text and "ValueError: x=1 is cursed" in text and "Traceback" in text
    assert "failed" not in store.keys()  # the folder is not a task
    # the task succeeds later (here: its record is stored as run_tasks stores it)
    store.write({**execute(Task(square, {"x": 1})), "key": tasks[1].key})
    assert store.failures() == []


@pytest.mark.parametrize("executor", ["inprocess", "local"])
def test_keep_going_runs_every_other_task_then_lists_the_failures(tmp_path, executor, monkeypatch):
    log = tmp_path / "calls.txt"
    tasks = grid(log, n=5, fail_at=1) + [Task(square, {"x": 3, "fail_at": 3, "seed": 7})]
    with pytest.raises(GridFailed) as info:
        run_tasks(tasks, store=tmp_path / "s", executor=executor, n_jobs=2, progress=False,
                  keep_going=True)  # fmt: skip
    err = info.value
    assert sorted(calls(log)) == [0, 1, 2, 3, 4]  # the failure stopped nothing
    assert sorted(f.key for f in err.failures) == sorted([tasks[1].key, tasks[5].key])
    assert isinstance(err, TaskFailed) and err.key == err.failures[0].key
    msg = str(err)
    assert msg.startswith("2 of 6 task(s) failed; the others ran")
    assert str(tmp_path / "s" / "failed") in msg and "x=1 is cursed" in msg
    store = TaskStore(tmp_path / "s")
    assert len(store.keys()) == 4 and len(store.failures()) == 2
    # the environment's default (a notebook's grid takes it without a parameter)
    monkeypatch.setenv("THESIS_SWEEP_KEEP_GOING", "1")
    with pytest.raises(GridFailed):
        run_tasks(grid(n=3, fail_at=0), store=tmp_path / "e", executor=executor, n_jobs=2,
                  progress=False)  # fmt: skip
    assert len(TaskStore(tmp_path / "e").keys()) == 2


def test_keep_going_survives_a_dead_worker(tmp_path):
    """A worker killed mid-task breaks joblib's pool: the grid gets a fresh one and goes on."""
    tasks = [Task(die, {"x": x, "die_at": 0}) for x in range(6)]
    with pytest.raises(GridFailed) as info:
        run_tasks(tasks, store=tmp_path, executor="local", n_jobs=2, progress=False,
                  keep_going=True)  # fmt: skip
    dead = {f.key for f in info.value.failures}
    assert tasks[0].key in dead  # (a task running beside it when the pool broke may fail too)
    stored = set(TaskStore(tmp_path).keys())
    assert stored | dead == {t.key for t in tasks} and len(stored) >= 4


def test_task_failed_keeps_the_error_type():
    task = Task(square, {"x": 1})
    err = TaskFailed.of(task, KeyError("seed"))
    assert isinstance(err, KeyError) and isinstance(err, TaskFailed)
    assert (
        str(err)
        == f"Task {task.key} failed: {__name__}:square({{\"x\":1}}) raised KeyError: 'seed'"
    )
    assert err.__cause__.args == ("seed",)
    odd = TaskFailed.of(task, FileNotFoundError(2, "gone"))
    assert isinstance(odd, FileNotFoundError) and isinstance(odd, TaskFailed)
    assert "gone" in str(odd)


def test_environment_selects_executor_and_jobs(monkeypatch):
    from thesis_lib.sweep import resolve_executor

    assert resolve_executor(None, None) == ("inprocess", 1)
    assert resolve_executor(None, 3) == ("local", 3)
    monkeypatch.setenv("THESIS_JOBS", "2")
    assert resolve_executor(None, None) == ("local", 2)
    monkeypatch.setenv("THESIS_EXECUTOR", "inprocess")
    assert resolve_executor(None, None) == ("inprocess", 2)
    assert resolve_executor("local", 1) == ("local", 1)
    with pytest.raises(ValueError, match="unknown executor 'dask'"):
        resolve_executor("dask", None)
    monkeypatch.setenv("THESIS_JOBS", "two")
    with pytest.raises(ValueError, match="THESIS_JOBS"):
        resolve_executor(None, None)


def test_duplicate_tasks_are_rejected(tmp_path):
    tasks = [*grid(n=2), Task(square, {"seed": 0, "x": 1, "log": None})]
    with pytest.raises(
        ValueError,
        match=r"appear twice in the grid, e.g. .*square\(\{\"log\":null,\"seed\":0,\"x\":1\}\)",
    ):
        run_tasks(tasks, store=tmp_path, progress=False)
    assert TaskStore(tmp_path).keys() == []  # rejected before anything ran


@pytest.mark.parametrize(
    "content, match",
    [
        ('{"key": "x", "rows": [', "Damaged task result .*Delete it"),
        ('["not", "a", "record"]', "not a task record"),
        ("{KEY_OTHER}", "holds task 'other'"),
    ],
)
def test_damaged_result_is_a_clear_error(tmp_path, content, match):
    tasks = grid(n=2)
    run_tasks(tasks, store=tmp_path, progress=False)
    path = TaskStore(tmp_path).path(tasks[1].key)
    if content == "{KEY_OTHER}":
        rec = json.loads(path.read_text())
        content = json.dumps({**rec, "key": "other"})
    path.write_text(content)
    with pytest.raises(RuntimeError, match=match) as info:
        run_tasks(tasks, store=tmp_path, progress=False)
    assert str(path) in str(info.value)
    # force recomputes it and repairs the file
    run_tasks(tasks, store=tmp_path, progress=False, force=True)
    assert TaskStore(tmp_path).read(tasks[1].key)["rows"][0]["x"] == 1


def test_ray_missing_is_a_clear_error(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(ImportError, match=r'pip install "\.\[ray\]"'):
        run_tasks(grid(n=1), executor="ray", progress=False)


def test_ray_resources_become_remote_options():
    from thesis_lib.sweep._executors import _ray_options

    assert _ray_options({"num_cpus": 1}) == {"num_cpus": 1}
    assert _ray_options({"num_cpus": 4, "num_gpus": 1, "memory": 2e9, "node:x": 0.1}) == {
        "num_cpus": 4,
        "num_gpus": 1,
        "memory": 2e9,
        "resources": {"node:x": 0.1},
    }


@pytest.mark.slow
def test_ray_local_instance_gives_the_same_rows_as_local(tmp_path, monkeypatch):
    ray = pytest.importorskip("ray", reason="Ray is an optional extra: pip install '.[ray]'")
    # Ray workers import this module by name: put tests/ (and the caller's path) on their path
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("RAY_ADDRESS", "")  # never join a cluster from a test
    log = tmp_path / "calls.txt"
    tasks = grid(log, n=4) + [
        Task(frame_task, {"x": 5}, resources={"num_cpus": 1, "num_gpus": 0}),
    ]
    local = run_tasks(tasks, store=tmp_path / "local", executor="local", n_jobs=2, progress=False)
    log.unlink()
    ray_tmp = tempfile.mkdtemp(prefix="ray-")  # short: Ray's socket paths must stay < 108 chars
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, _temp_dir=ray_tmp)
    try:
        on_ray = run_tasks(tasks, store=tmp_path / "ray", executor="ray", progress=False)
        pd.testing.assert_frame_equal(on_ray, local)
        assert sorted(calls(log)) == [0, 1, 2, 3]
        stored = TaskStore(tmp_path / "ray")
        assert stored.keys() == sorted(t.key for t in tasks)
        # a failing task on Ray: its config in the message, finished tasks stay stored
        bad = grid(n=3, fail_at=2)
        with pytest.raises(TaskFailed, match=r'"x":2.*cursed'):
            run_tasks(bad, store=tmp_path / "bad", executor="ray", progress=False)
        assert bad[2].key not in TaskStore(tmp_path / "bad").keys()
        with pytest.raises(GridFailed, match="1 of 4 task"):  # keep going: the others run
            run_tasks(grid(n=4, fail_at=0), store=tmp_path / "kg", executor="ray",
                      progress=False, keep_going=True)  # fmt: skip
        assert len(TaskStore(tmp_path / "kg").keys()) == 3
    finally:
        ray.shutdown()
        shutil.rmtree(ray_tmp, ignore_errors=True)  # leave no session folder behind
    # without a Ray of its own, the executor starts a local instance for the grid and stops it
    log.unlink()
    again = run_tasks(tasks, store=tmp_path / "ray2", executor="ray", n_jobs=2, progress=False)
    pd.testing.assert_frame_equal(again, local)
    assert sorted(calls(log)) == [0, 1, 2, 3]
    assert not ray.is_initialized()


# --- thesis run / thesis book: the options reach the chapter's kernel -------------------------

ENV_NAMES = ["THESIS_EXECUTOR", "THESIS_JOBS", "RAY_ADDRESS", "THESIS_SWEEP_FORCE", "TQDM_DISABLE"]


def _fake_project(root: Path) -> None:
    """A one-chapter project whose notebook writes its kernel's sweep environment to a file."""
    import nbformat

    (root / "notebooks").mkdir()
    (root / "params").mkdir()
    (root / "_toc.yml").write_text(
        "format: jb-book\nroot: intro\nchapters:\n- file: book/generated/99_env\n"
    )
    params = nbformat.v4.new_code_cell('out = "env.json"')
    params.metadata["tags"] = ["parameters"]
    dump = nbformat.v4.new_code_cell(
        "import json, os\n"
        f"names = {ENV_NAMES!r}\n"
        "json.dump({k: os.environ.get(k) for k in names}, open(out, 'w'))"
    )
    nb = nbformat.v4.new_notebook(cells=[params, dump])
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nbformat.write(nb, root / "notebooks" / "99_env.ipynb")
    (root / "params" / "99_env.smoke.yml").write_text('out: "env.json"\n')


def test_thesis_run_options_reach_the_kernel(tmp_path, monkeypatch):
    from thesis_lib.cli import main

    _fake_project(tmp_path)
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    for name in ENV_NAMES:
        monkeypatch.delenv(name, raising=False)
    out = tmp_path / "env.json"
    rc = main(["run", "99_env", "-q", "-p", "out", str(out), "-j", "3", "--force"])
    assert rc == 0
    assert json.loads(out.read_text()) == {
        "THESIS_EXECUTOR": None,  # not given: run_tasks picks local for 3 jobs
        "THESIS_JOBS": "3",
        "RAY_ADDRESS": None,
        "THESIS_SWEEP_FORCE": "1",
        "TQDM_DISABLE": "1",
    }
    assert all(name not in os.environ for name in ENV_NAMES)  # the caller's env is restored
    rc = main(["run", "99_env", "-q", "-p", "out", str(out), "--executor", "inprocess"])
    assert rc == 0
    assert json.loads(out.read_text())["THESIS_EXECUTOR"] == "inprocess"
    assert json.loads(out.read_text())["THESIS_JOBS"] is None


def test_thesis_run_option_errors(tmp_path, monkeypatch, capsys):
    import sys

    from thesis_lib.cli import main

    _fake_project(tmp_path)
    monkeypatch.setenv("THESIS_PROJECT_ROOT", str(tmp_path))
    assert main(["run", "99_env", "-j", "0"]) == 1
    assert "at least 1" in capsys.readouterr().err
    assert main(["run", "99_env", "--executor", "local", "--address", "head:6379"]) == 1
    assert "needs the Ray executor" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "ray", None)  # Ray not installed
    assert main(["run", "99_env", "--executor", "ray"]) == 1
    assert 'pip install ".[ray]"' in capsys.readouterr().err
    assert not (tmp_path / "env.json").exists()  # failed before the notebook ran


def test_thesis_book_keeps_j_for_chapters():
    from thesis_lib.cli import build_parser

    args = build_parser().parse_args(["book", "-j", "2", "--task-jobs", "4", "--executor", "local"])
    assert (args.jobs, args.task_jobs, args.executor, args.force) == (2, 4, "local", False)
    args = build_parser().parse_args(["run", "04_hdt", "--task-jobs", "2", "--address", "h:1"])
    assert (args.task_jobs, args.address) == (2, "h:1")


def test_local_grids_leave_joblib_parallel_working():
    """A local grid's process pool is joblib's reusable executor; a ``joblib.Parallel`` later in
    the same process reuses it. Made by loky's factory it lacked joblib's temp-folder manager,
    and that Parallel call raised AttributeError ('_temp_folder_manager')."""
    from joblib import Parallel, delayed

    from thesis_lib.sweep import probe

    rows = run_tasks(
        [Task(probe, {"i": i}) for i in range(3)], executor="local", n_jobs=2, progress=False
    )
    assert sorted(rows["i"]) == [0, 1, 2]
    assert Parallel(n_jobs=2)(delayed(abs)(-i) for i in range(4)) == [0, 1, 2, 3]


def test_a_dirty_checkouts_record_names_the_changed_files(tmp_path, monkeypatch):
    """The store's records carry :func:`thesis_lib.provenance.commit_record` as it is, so a
    ``-dirty`` commit comes with ``git_dirty``."""
    import thesis_lib.sweep as sw

    dirty = {"git_commit": "abc123-dirty", "git_dirty": ["README.md", "src/x.py"]}
    monkeypatch.setattr(sw, "commit_record", lambda: dict(dirty))
    tasks = [Task(square, {"x": 2, "seed": 0})]
    run_tasks(tasks, store=tmp_path, executor="inprocess", progress=False)
    rec = TaskStore(tmp_path).read(tasks[0].key)
    assert {k: rec[k] for k in dirty} == dirty
