"""The documentation site builds with warnings as errors and has the pages it promises."""

import importlib.util
import os
import subprocess
import sys

import pytest

from conftest import ROOT
from parmps import validation

DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    result = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q",
                             "-b", "html", "-d", str(out / "doctrees"), str(DOCS), str(out)],
                            capture_output=True, text=True, timeout=240, cwd=ROOT)
    assert result.returncode == 0, (result.stdout + result.stderr)[-4000:]
    return out


def test_the_site_builds_with_warnings_as_errors(site):
    for page in ("index", "getting_started", "writing_cases", "output", "parallel",
                 "long_runs", "performance", "method", "design", "history",
                 "_generated/case_reference", "_generated/api", "validation/index"):
        assert (site / f"{page}.html").is_file(), page


def test_the_case_reference_page_shows_the_schema(site):
    text = (site / "_generated" / "case_reference.html").read_text()
    assert "re_laplacian" in text and "escaped_fluid" in text


def test_the_api_page_lists_the_public_modules(site):
    spec = importlib.util.spec_from_file_location("conf", DOCS / "conf.py")
    conf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conf)
    modules = conf.public_modules()
    assert {"parmps.config", "parmps.schema", "parmps.result", "parmps.validation",
            "parmps.fluid.ppe"} <= set(modules)
    text = (site / "_generated" / "api.html").read_text()
    missing = [name for name in modules if f'id="module-{name}"' not in text]
    assert missing == []


def test_every_validation_has_its_page():
    pages = {name[:-3] for name in os.listdir(DOCS / "validation") if name.endswith(".md")}
    assert set(validation.names()) <= pages
