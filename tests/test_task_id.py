"""A task function's stable name (:func:`thesis_lib.sweep.task_id`): moving a study's task
function to another module must keep the keys of the tasks already stored."""

from __future__ import annotations

import json

import pytest

from thesis_lib.sweep import Task, config_hash, run_tasks, task_id


@task_id("thesis_lib.chapters.somewhere:old_name")
def moved(config: dict) -> list[dict]:
    return [{"x": config["x"] * 2}]


def plain(config: dict) -> list[dict]:
    return [{"x": config["x"]}]


def test_the_key_is_that_of_the_old_path():
    t = Task(moved, {"x": 3})
    old = config_hash({"fn": "thesis_lib.chapters.somewhere:old_name", "config": {"x": 3}})
    assert t.key == old
    assert Task(plain, {"x": 3}).key == config_hash({"fn": f"{__name__}:plain", "config": {"x": 3}})
    assert Task(plain, {"x": 3}).key != t.key


def test_records_name_the_task_id_and_the_function_still_runs(tmp_path):
    rows = run_tasks([Task(moved, {"x": 3})], tmp_path, executor="inprocess", progress=False)
    assert rows["x"].tolist() == [6]
    (rec,) = [json.loads(p.read_text()) for p in tmp_path.glob("*.json")]
    assert rec["fn"] == "thesis_lib.chapters.somewhere:old_name"


@pytest.mark.parametrize("bad", ["no_colon", ":f", "mod:"])
def test_a_task_id_is_module_colon_qualname(bad):
    with pytest.raises(ValueError, match="module:qualname"):
        task_id(bad)
