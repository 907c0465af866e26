"""Validation cases as data: ``validation/<name>/validation.toml``.

Each file names the case (``case = "cases/<name>.toml"``, relative to the
repository), an optional reference data file beside it, the metric (a function of
``parmps.tools.analysis`` and its keyword arguments, ``[metric]``), how a validation
run is made (``[run]``), settings of scripts/study.py's sweeps (``[study]``),
further cases it compares (``[other_cases]``) and the tolerances the tests assert
(``[tolerance]``). Physical constants live in the case files only.

Where the data is: an installed package carries ``validation/``, ``cases/`` and
``tests/cases/`` in ``parmps/_data/`` (setup.py copies them there when a wheel is
built); a source checkout (an editable install) reads them from the repository
itself. :data:`ROOT` is whichever holds them. ``load`` takes another ``directory``
for a tree elsewhere.

Running validations and benchmarks: :mod:`parmps.validation.command`
(``python -m parmps validate``), :mod:`parmps.validation.bench` (``python -m parmps
bench``), both through the one launcher :mod:`parmps.validation.launch`.
"""

import math
import os
import tomllib
from dataclasses import dataclass

from parmps.errors import CaseError

PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA_FOLDERS = ("validation", "cases", os.path.join("tests", "cases"))


def data_root():
    """The folder holding ``validation/`` and ``cases/``: the installed package's ``_data``,
    else the source checkout the package sits in."""
    installed = os.path.join(PACKAGE, "_data")
    if os.path.isdir(os.path.join(installed, "validation")):
        return installed
    return os.path.dirname(PACKAGE)


ROOT = data_root()
DIRECTORY = os.path.join(ROOT, "validation")
FILE_NAME = "validation.toml"
TABLES = ("metric", "run", "study", "other_cases", "tolerance", "judge")
KEYS = ("case", "reference") + TABLES


@dataclass(frozen=True)
class Validation:
    """One validation: its case, reference data, metric and tolerances (absolute paths)."""

    name: str
    folder: str
    case_path: str
    reference: str | None
    metric: dict
    run: dict
    study: dict
    other_cases: dict
    tolerance: dict
    judge: dict

    @property
    def metric_function(self):
        """The metric: a function of ``parmps.tools.analysis``, (result, case, ...) -> dict."""
        from parmps.tools import analysis
        return getattr(analysis, self.metric["function"])

    @property
    def metric_arguments(self):
        """The metric's keyword arguments from ``[metric]`` (and the reference, if any)."""
        arguments = {key: value for key, value in self.metric.items() if key != "function"}
        if self.reference is not None:
            arguments["reference"] = self.reference
        if isinstance(arguments.get("references"), dict):
            # Several reference files (one per probe), named relative to the folder.
            arguments["references"] = {key: os.path.join(self.folder, value)
                                       for key, value in arguments["references"].items()}
        if isinstance(arguments.get("level_reference"), str):
            # A second record of the same experiment (its water heights), beside the first.
            arguments["level_reference"] = os.path.join(self.folder,
                                                        arguments["level_reference"])
        return arguments

    def measure(self, result, **overrides):
        """The metric of a result file, judged against the case that result was run with."""
        from parmps.tools import analysis
        arguments = dict(self.metric_arguments, **overrides)
        return self.metric_function(result, analysis.result_case(result), **arguments)

    def run_arguments(self, overrides=()):
        """How a validation run is made, from ``[run]``: (end_time, sets). ``end_time`` is
        ``[run] end_time`` [s], or ``until`` over the metric's time scale (``time_scale``, a
        function of ``parmps.tools.analysis`` of the case), or None (the case's own end);
        ``sets`` are ``[run] sets``, ``time.output_interval`` from ``[run] output_interval``
        and ``overrides``, as ``--set`` takes them. ``[run] beside`` names cases of
        ``[other_cases]`` run the same way for a metric that compares with them
        (parmps.validation.command.run_beside)."""
        from parmps.tools import analysis
        run = self.run
        sets = list(run.get("sets", []))
        if "output_interval" in run:
            sets.append(f"time.output_interval={run['output_interval']!r}")
        sets += list(overrides)
        if "end_time" in run:
            return float(run["end_time"]), sets
        if "until" in run:
            scale = getattr(analysis, run["time_scale"])(self.case(sets))
            return float(run["until"]) / scale, sets
        return None, sets

    def verdicts(self, measured):
        """Each tolerance applied to what :meth:`measure` returned: name -> {value, tolerance,
        pass}. A number bounds the absolute value, a pair [low, high] the value itself.
        ``[judge]`` maps a tolerance to the metric's name for it when they differ, or to a
        list of paths into a nested result (``"P1.means.0.error"``: keys, and indexes of
        lists; a ``<path>_raw`` beside it, the figure against the record as published, is
        shown as ``raw`` and ``raw_pass``, not judged); with ``judged`` (a list of probes), each tolerance applies to every probe's
        ``<name>_error``. Tolerances the metric does not measure (the tests judge those
        from the run) are left out."""
        verdicts = {}
        for key, bound in self.tolerance.items():
            if key == "judged" or isinstance(bound, dict):
                continue
            name = self.judge.get(key, key)
            if isinstance(name, list):
                for path in name:
                    value = _lookup(measured, path)
                    if isinstance(value, (int, float)):
                        verdicts[path] = _verdict(value, bound)
                        raw = _lookup(measured, f"{path}_raw")
                        if isinstance(raw, (int, float)):
                            # The same figure against the record as published (its clock
                            # not shifted): shown beside, not judged.
                            beside = _verdict(raw, bound)
                            verdicts[path].update(raw=beside["value"], raw_pass=beside["pass"])
            elif "judged" in self.tolerance:
                for probe in self.tolerance["judged"]:
                    value = measured.get(probe, {}).get(f"{name}_error")
                    if value is not None:
                        verdicts[f"{probe}.{name}_error"] = _verdict(value, bound)
            elif isinstance(measured.get(name), (int, float)):
                verdicts[name] = _verdict(measured[name], bound)
        return verdicts

    def raw_case(self, path=None):
        """The case file as parsed TOML (before validation): the base of --set overrides."""
        from parmps import config
        path = path or self.case_path
        with open(path, "rb") as handle:
            return config.load_text(handle.read().decode("utf-8"), path)

    def case(self, overrides=(), path=None):
        """The validated case, with ``SECTION.KEY=VALUE`` overrides applied as --set would."""
        from parmps import config, schema
        raw = self.raw_case(path)
        for assignment in overrides:
            config.apply_override(raw, assignment)
        return schema.validate(raw)


def _lookup(measured, path):
    """The item at a dotted path of a nested result (keys, and indexes of lists), or None."""
    node = measured
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return None
    return node


def _verdict(value, bound):
    value = float(value)
    if isinstance(bound, list):
        passed = bound[0] <= value <= bound[1]
    else:
        passed = abs(value) <= bound
    return {"value": value if math.isfinite(value) else str(value), "tolerance": bound,
            "pass": bool(passed)}


def names(directory=DIRECTORY):
    """The validations present: the folders of ``directory`` holding a validation.toml."""
    return sorted(entry for entry in os.listdir(directory)
                  if os.path.isfile(os.path.join(directory, entry, FILE_NAME)))


def load(name, directory=DIRECTORY):
    """Read ``<directory>/<name>/validation.toml``; a bad file raises a one-line CaseError."""
    folder = os.path.join(directory, name)
    path = os.path.join(folder, FILE_NAME)
    try:
        with open(path, "rb") as handle:
            raw = tomllib.load(handle)
    except FileNotFoundError:
        raise CaseError(f"no validation '{name}': {path} not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{path}: not valid TOML: {exc}") from None
    for key in raw:
        if key not in KEYS:
            raise CaseError(f"{path}: unknown key '{key}' (valid: {', '.join(KEYS)})")
    if not isinstance(raw.get("case"), str):
        raise CaseError(f"{path}: 'case' must name the case file")
    tables = {table: raw.get(table, {}) for table in TABLES}
    for table, value in tables.items():
        if not isinstance(value, dict):
            raise CaseError(f"{path}: [{table}] must be a table")
    if "function" not in tables["metric"]:
        raise CaseError(f"{path}: [metric] needs 'function' (in parmps/tools/analysis.py)")
    root = os.path.dirname(os.path.abspath(directory))
    validation = Validation(
        name=name, folder=folder,
        case_path=os.path.join(root, raw["case"]),
        reference=os.path.join(folder, raw["reference"]) if "reference" in raw else None,
        other_cases={key: os.path.join(root, value)
                     for key, value in tables["other_cases"].items()},
        **{table: tables[table] for table in TABLES if table != "other_cases"})
    references = validation.metric_arguments.get("references")
    missing = [p for p in [validation.case_path, validation.reference,
                           validation.metric_arguments.get("level_reference"),
                           *validation.other_cases.values(),
                           *(references.values() if isinstance(references, dict) else ())]
               if p and not os.path.isfile(p)]
    if missing:
        raise CaseError(f"{path}: {missing[0]} not found")
    from parmps.tools import analysis
    if "until" in validation.run and \
            not callable(getattr(analysis, validation.run.get("time_scale", ""), None)):
        raise CaseError(f"{path}: [run] until needs time_scale, a function of "
                        f"parmps/tools/analysis.py")
    if not callable(getattr(analysis, validation.metric["function"], None)):
        raise CaseError(f"{path}: metric function '{validation.metric['function']}' is not in "
                        f"parmps/tools/analysis.py")
    return validation


def scaled_overrides(raw, factor):
    """``SECTION.KEY=VALUE`` overrides that scale a case's scene by ``factor``.

    ``raw``: the parsed case. Scales the domain, the fluid blocks, tanks and wall
    boxes; the spacing is the caller's choice (l0 relative to the scene, or not).
    """
    overrides = [f"domain.{key}={[v * factor for v in raw['domain'][key]]}"
                  for key in ("lower", "upper")]
    for section in ("fluid_block", "tank", "wall_box"):
        for index, table in enumerate(raw.get(section, [])):
            for key in ("lower", "upper"):
                if key in table:  # a fluid block of a mesh or shape may have no box
                    overrides.append(f"{section}.{index}.{key}="
                                     f"{[v * factor for v in table[key]]}")
    return overrides
