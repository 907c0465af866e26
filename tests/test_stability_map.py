"""scripts/stability_map.py's report: the table it writes, where it puts it, and that
scripts/study.py keeps it when it rewrites the report (no runs here)."""

import importlib.util
import sys

from conftest import ROOT


def _script(name):
    """A script of scripts/ as a module, from its file (scripts/ is not a package); known by
    its name, as the scripts import each other when run."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


stability_map = _script("stability_map")
study = _script("study")

REPORT = "# Report\n\n## Stability map\n\n| a | b |\n| --- | --- |\n\n## Guards\n\ntext\n"


def _row(ratio, factor, outcome, **extra):
    return dict(density_ratio=ratio, inflow_factor=factor, outcome=outcome, wall=1.0,
                end=0.3, volume_error=1e-8, end_time=0.3, **extra)


def test_table_counts_every_outcome_and_quotes_each_message():
    rows = [_row(1.0, 1.0, "ran to the end"),
            _row(0.1, 10.0, "stopped: step 5: body 'box' blew up",
                 retry=dict(outcome="ran to the end", wall=2.0, dt_max=5e-4)),
            _row(0.1, 1.0, "ran to the end with NON-FINITE values (no message)")]
    text = stability_map.markdown({"ranks": 1, "box": {"u0": 0.1, "rows": rows}}, "cmd")
    assert ". stopped: step 5: body 'box' blew up" in text  # a numbered note
    assert "with time.dt_max = 0.0005 s: ran" in text
    assert ("3 runs: 1 ran to the end, 1 stopped with a message, 1 ended otherwise" in text)


def test_the_block_goes_into_the_stability_section_once_and_study_keeps_it(tmp_path):
    path = tmp_path / "validation.md"
    path.write_text(REPORT)
    first = f"{stability_map.BEGIN}\nfirst\n{stability_map.END}"
    stability_map.splice(path, first)
    text = path.read_text()
    assert text.index("first") < text.index("## Guards") and text.index("| a | b |") < \
        text.index("first")
    second = f"{stability_map.BEGIN}\nsecond\n{stability_map.END}"
    stability_map.splice(path, second)
    text = path.read_text()
    assert "first" not in text and text.count(stability_map.BEGIN) == 1
    assert study.coupled_stability_block(path) == second
