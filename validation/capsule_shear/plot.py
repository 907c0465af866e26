#!/usr/bin/env python3
"""The capsule in simple shear at every Ca of the validation's study.

Usage: python validation/capsule_shear/plot.py [WORK] [--run] [--ranks N] [--figure PATH]

For each Ca of ``[study] capillary`` in validation/capsule_shear/validation.toml, reads
WORK/ca<Ca>/result.h5 (default WORK: out/capsule_shear), or with ``--run`` first runs
cases/capsule_shear.toml there with G_s = rho nu a gamma_dot / Ca and K_d = G_s (``--set``);
prints one line per Ca (steady D, D/Ca, each reference and the error against it, the drift
over the steady window, the volume error) and draws docs/capsule_shear.png: D(gamma_dot t)
for each Ca, and the steady D(Ca) over the references and small-deformation theory's
D = 25/4 Ca.
"""

import logging
import pathlib
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from parmps import validation  # noqa: E402
from parmps.tools import analysis  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
log = logging.getLogger("capsule_shear")
SOURCES = {"ramanujan_pozrikidis_1998": "Ramanujan & Pozrikidis 1998",
           "doddi_bagchi_2008": "Doddi & Bagchi 2008"}


def moduli_sets(check, capillary):
    """The --set overrides that give the case Ca = ``capillary`` (G_s = K_d)."""
    case = check.case()
    _, _, rate = analysis.simple_shear(case)
    radius = case["body"][0]["radius"]
    modulus = case["fluid"]["density"] * case["fluid"]["viscosity"] * radius * rate / capillary
    return [f"body.0.shear_modulus={modulus!r}", f"body.0.local_area_modulus={modulus!r}"]


def run(check, capillary, out, ranks):
    command = ["mpirun", "-n", str(ranks), sys.executable, "-m", "parmps", check.case_path,
               "--output", str(out)]
    for assignment in moduli_sets(check, capillary):
        command += ["--set", assignment]
    log.info("%s", " ".join(command))
    subprocess.run(command, check=True)


def main(argv):
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    args = [a for a in argv if not a.startswith("--")]
    figure = ROOT / "docs" / "capsule_shear.png"
    if "--figure" in argv:
        figure = pathlib.Path(argv[argv.index("--figure") + 1])
        args.remove(str(figure))
    ranks = int(argv[argv.index("--ranks") + 1]) if "--ranks" in argv else 1
    if "--ranks" in argv:
        args.remove(str(ranks))
    work = pathlib.Path(args[0]) if args else ROOT / "out" / "capsule_shear"
    check = validation.load("capsule_shear")
    study = check.study
    measured = {}
    for capillary in study["capillary"]:
        out = work / f"ca{capillary:g}"
        if "--run" in argv and not (out / "result.h5").exists():
            run(check, capillary, out, ranks)
        if (out / "result.h5").exists():
            try:
                measured[capillary] = check.measure(out / "result.h5")
            except ValueError as exc:   # a run that has not reached the steady window
                log.info("Ca %g: %s", capillary, exc)
    report(measured, study)
    draw(measured, check.reference, figure)


def report(measured, study):
    log.info("Ca       steady D  D/Ca   drift    volume err  against the references")
    for capillary, m in measured.items():
        against = "  ".join(f"{SOURCES[s]} {m[s]:.3f} ({m[s + '_error']:+.1%})"
                            for s in SOURCES if s in m)
        log.info("%-8g %.4f   %.2f   %+.4f  %.1e     %s (to gamma_dot t = %.2f)", capillary,
                 m["steady"], m["slope"], m["drift"], m["volume_error"], against,
                 m["end_strain"])
    smallest = measured.get(study["slope_capillary"])
    if smallest is not None:
        low, high = study["slope"]
        log.info("D/Ca at Ca %g: %.3f (target %.4g-%.4g: %s)", study["slope_capillary"],
                 smallest["slope"], low, high,
                 "met" if low <= smallest["slope"] <= high else "missed")


def draw(measured, reference, figure):
    left, right = plt.subplots(1, 2, figsize=(10, 4))[1]
    for capillary, m in measured.items():
        left.plot(m["strain"], m["deformation"], label=f"Ca = {capillary:g}")
    left.set_xlabel(r"$\dot\gamma t$")
    left.set_ylabel("D")
    left.legend()
    table = analysis.reference_table(reference)
    for source, name in SOURCES.items():
        right.plot(table["Ca"], table[source], "s--", label=name)
    capillaries = sorted(measured)
    right.plot(capillaries, [measured[c]["steady"] for c in capillaries], "o-", label="parmps")
    small = [c for c in table["Ca"] if c <= 0.05]
    right.plot(small, [6.25 * c for c in small], ":", color="grey", label="D = 25/4 Ca")
    right.set_xlabel("Ca")
    right.set_ylabel(r"steady D ($\dot\gamma t$ 6-8)")
    right.legend()
    plt.tight_layout()
    plt.savefig(figure, dpi=120)
    log.info("figure: %s", figure)


if __name__ == "__main__":
    main(sys.argv[1:])
