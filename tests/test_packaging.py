"""pyproject.toml and requirements.txt agree: the declared ranges admit the lock, the package
data patterns cover every data file the library ships."""

from __future__ import annotations

import fnmatch
import tomllib

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from thesis_lib.book import project_root

ROOT = project_root()
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _lock() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if "==" in line and not line.startswith("-"):
            name, version = line.split("==", 1)
            pins[canonicalize_name(name.split("[")[0])] = version.strip()
    return pins


def _declared() -> list[Requirement]:
    project = PYPROJECT["project"]
    reqs = [Requirement(r) for r in project["dependencies"]]
    for extra in project.get("optional-dependencies", {}).values():
        reqs += [Requirement(r) for r in extra]
    return [r for r in reqs if canonicalize_name(r.name) != "thesis-lib"]


def test_declared_ranges_admit_the_locked_versions():
    lock = _lock()
    assert len(lock) > 50, "requirements.txt is the lock: one name==version a line"
    runtime = [Requirement(r) for r in PYPROJECT["project"]["dependencies"]]
    assert all(r.specifier for r in runtime), "every runtime dependency has a lower bound"
    for req in runtime:
        assert canonicalize_name(req.name) in lock, f"{req.name} is declared but not locked"
    for req in _declared():
        pinned = lock.get(canonicalize_name(req.name))
        if pinned is not None:
            assert req.specifier.contains(pinned, prereleases=True), (
                f"pyproject asks {req} but requirements.txt locks {req.name}=={pinned}"
            )


def test_package_data_covers_every_shipped_data_file():
    patterns = PYPROJECT["tool"]["setuptools"]["package-data"]["thesis_lib"]
    pkg = ROOT / "src" / "thesis_lib"
    data_files = [
        p.relative_to(pkg).as_posix()
        for p in pkg.rglob("*")
        if p.is_file()
        and p.suffix not in (".py", ".pyc", ".nbi", ".nbc")
        and "__pycache__" not in p.parts
    ]
    assert data_files, "the library ships reference tables, expert policies and MuJoCo assets"
    missing = [f for f in data_files if not any(fnmatch.fnmatch(f, pat) for pat in patterns)]
    assert not missing, f"not in [tool.setuptools.package-data]: {missing}"
