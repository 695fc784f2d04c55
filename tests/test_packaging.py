"""The set-up files agree with each other, and notebooks are committed without outputs."""

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
#: conda-forge package names that differ from their PyPI names.
CONDA_TO_PYPI = {"pytorch": "torch", "pysoundfile": "soundfile"}
#: In environment.yml but not a dependency of the package itself.
CONDA_ONLY = {"python", "pip"}


def _lower_bounds_from_pyproject() -> dict[str, str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = [
        requirement
        for group in (project["dependencies"], *project["optional-dependencies"].values())
        for requirement in group
    ]
    bounds = {}
    for requirement in requirements:
        match = re.fullmatch(r"([A-Za-z0-9_.-]+)>=([0-9.]+)", requirement)
        assert match, f"pyproject.toml: {requirement!r} should be 'name>=lower_bound'"
        bounds[match[1].lower()] = match[2]
    return bounds


def _lower_bounds_from_environment() -> dict[str, str]:
    environment = yaml.safe_load((ROOT / "environment.yml").read_text())
    assert environment["channels"][0] == "conda-forge"
    bounds = {}
    for entry in environment["dependencies"]:
        if isinstance(entry, dict):  # the pip section: the repository itself and PyPI-only extras
            assert entry["pip"][0] == "--editable ."
            entries = entry["pip"][1:]
            bounds.update(
                dict(re.fullmatch(r"([A-Za-z0-9_.-]+)>=([0-9.]+)", e).groups() for e in entries)
            )
            continue
        match = re.fullmatch(
            r"([A-Za-z0-9_.-]+)(?:\[version='>=([0-9.]+)'.*\]|>=([0-9.]+)|=.*)?", entry
        )
        assert match, f"environment.yml: cannot read {entry!r}"
        name = CONDA_TO_PYPI.get(match[1].lower(), match[1].lower())
        if name not in CONDA_ONLY:
            bounds[name] = match[2] or match[3]
    return bounds


def test_environment_yml_and_pyproject_do_not_drift_apart():
    assert _lower_bounds_from_environment() == _lower_bounds_from_pyproject()


def test_lock_pins_every_dependency_exactly():
    pinned = {}
    for line in (ROOT / "requirements-lock.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            assert version, f"requirements-lock.txt: {line!r} is not pinned with =="
            pinned[name.lower().replace("_", "-")] = version
    for name in _lower_bounds_from_pyproject():
        assert name.replace("_", "-") in pinned, f"{name} is missing from requirements-lock.txt"
    assert "+" not in pinned["torch"], "pin the public torch version; the Makefile picks the build"


@pytest.mark.parametrize(
    "notebook", sorted((ROOT / "notebooks").glob("*.ipynb")), ids=lambda p: p.name
)
def test_notebooks_are_committed_without_outputs(notebook):
    cells = json.loads(notebook.read_text())["cells"]
    for index, cell in enumerate(cells):
        if cell["cell_type"] == "code":
            assert not cell["outputs"], f"{notebook.name} cell {index} has outputs: run nbstripout"
            assert cell["execution_count"] is None, f"{notebook.name} cell {index} has a count"


def test_binder_environment_is_the_course_environment_without_the_editable_install():
    def entries(path):
        lines = (ROOT / path).read_text().splitlines()
        return [line for line in lines if not line.startswith("#") and "--editable ." not in line]

    assert entries("binder/environment.yml") == entries("environment.yml")
    assert "--editable ." in (ROOT / "binder" / "postBuild").read_text()


@pytest.mark.parametrize(
    ("path", "schema"),
    [
        ("CITATION.cff", "vendor.citation-file-format"),
        (".github/workflows/course.yml", "vendor.github-workflows"),
    ],
)
def test_file_validates_against_its_schema(path, schema):
    """check-jsonschema ships these schemas, so this needs no network."""
    command = [sys.executable, "-m", "check_jsonschema", "--builtin-schema", schema, path]
    checked = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_licence_is_declared_where_tools_read_it():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["license"] == "MIT" and citation["version"] == project["version"]
