"""The README fits on a screen, and its short commands run as written."""

import re

import pytest

from conftest import ROOT, run_parmps

README = (ROOT / "README.md").read_text()


def _blocks(language):
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_the_readme_is_at_most_150_lines():
    assert len(README.splitlines()) <= 150


def test_the_first_case_is_valid(tmp_path):
    (case,) = _blocks("toml")
    path = tmp_path / "still.toml"
    path.write_text(case)
    result = run_parmps([path, "--check"], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert '"fluid"' in result.stdout


@pytest.mark.parametrize("line", [line.split("#")[0].strip()
                                  for block in _blocks("sh") for line in block.splitlines()
                                  if "--check" in line])
def test_the_readme_check_commands_run(line):
    words = line.split()
    assert words[:3] == ["python", "-m", "parmps"]
    result = run_parmps(words[3:], timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]


def test_the_first_case_runs_and_the_python_example_reads_it(tmp_path, monkeypatch):
    (case,) = _blocks("toml")
    (example,) = _blocks("python")
    (tmp_path / "still.toml").write_text(case)
    result = run_parmps([tmp_path / "still.toml", "-o", tmp_path / "out" / "still",
                         "--end-time", "0.02", "--set", "time.output_interval=0.01"],
                        timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    monkeypatch.chdir(tmp_path)          # the example reads out/still, as the README says
    exec(compile(example, "README.md", "exec"), {})
