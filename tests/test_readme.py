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


def _short_commands():
    """The README's python -m parmps lines that check a case or run it for less than 1 s."""
    lines = [line.split("#")[0].strip() for block in _blocks("sh")
             for line in block.splitlines() if line.startswith("python -m parmps")]
    return [line for line in lines if "--check" in line or
            ("--end-time" in line and float(line.split("--end-time")[1].split()[0]) < 1.0)]


def test_the_readme_has_short_commands_to_run():
    assert len(_short_commands()) >= 2


@pytest.mark.parametrize("line", _short_commands())
def test_the_readme_short_commands_run(line, tmp_path):
    words = line.split()
    assert words[:3] == ["python", "-m", "parmps"]
    # A run writes into tmp_path rather than the checkout's out/.
    extra = [] if "--check" in words else ["-o", tmp_path]
    result = run_parmps(words[3:] + extra, timeout=300)
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
