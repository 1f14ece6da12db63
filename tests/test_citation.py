"""CITATION.cff is valid Citation File Format 1.2.0 and names the package's version."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import jsonschema
import pytest
import yaml

import grail_bench

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = json.loads((ROOT / "tests" / "fixtures" / "cff" / "schema-1.2.0.json").read_text(encoding="utf-8"))


def _citation() -> dict:
    return yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))


def _validator() -> jsonschema.protocols.Validator:
    cls = jsonschema.validators.validator_for(SCHEMA)
    return cls(SCHEMA, format_checker=cls.FORMAT_CHECKER)


def test_citation_is_valid_cff_1_2_0():
    citation = _citation()
    assert citation["cff-version"] == "1.2.0"
    errors = sorted(_validator().iter_errors(citation), key=lambda e: list(e.path))
    assert not errors, "; ".join(f"{'/'.join(map(str, e.path))}: {e.message}" for e in errors)


def test_the_schema_check_can_fail():
    broken = copy.deepcopy(_citation())
    del broken["authors"]
    broken["license"] = "Not-A-Licence"
    messages = [e.message for e in _validator().iter_errors(broken)]
    assert any("authors" in m for m in messages) and len(messages) >= 2


def test_citation_version_and_licence_are_the_package_s():
    citation = _citation()
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert citation["version"] == project["version"] == grail_bench.__version__
    assert citation["license"] == project["license"] == "MIT"


def test_citation_names_the_grail_paper():
    paper = _citation()["preferred-citation"]
    assert paper["title"] == "GRAIL: Goal Recognition Alignment through Imitation Learning"
    assert "AAMAS 2026" in paper["collection-title"] and paper["year"] == 2026


@pytest.mark.parametrize("field", ["title", "message", "authors"])
def test_citation_has_what_github_shows(field):
    assert _citation()[field]
