"""ParaView opens result.xdmf with one vertex cell per particle, so its default view shows them.

The ParaView tests run only where ParaView is installed (Debian: apt-get install
paraview python3-paraview xvfb); scripts/render_paraview.py opens and renders
the result under pvbatch, as a user would check it. The runs are a few
steps of small cases, so the file takes seconds.
"""

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import CASES, ROOT, run_parmps

pytestmark = pytest.mark.timeout(300)

INSTALL = "apt-get install paraview python3-paraview xvfb"
POINT_ARRAYS = ["id", "kind", "number_density", "pressure", "velocity"]


def write_growing_result(directory):
    """A result whose particle count goes 3, 5, 4, written by the frame writer itself."""
    from mpi4py import MPI

    from parmps.core.particles import Particles
    from parmps.io.frames import FrameWriter
    from parmps.io.result import ResultFile
    result = ResultFile(MPI.COMM_SELF, str(directory), "# no case\n")
    writer = FrameWriter(result)
    for step, count in enumerate((3, 5, 4)):
        x = np.arange(count, dtype=float)
        writer.write(step, 0.1 * step, 0.1, Particles({
            "id": np.arange(count)[::-1] + 10 * step,
            "position": np.column_stack([x, x % 2]),
            "pressure": x,
        }))
        writer.publish()
    result.close(True)


def test_vertex_index_grows_to_the_largest_frame(tmp_path):
    write_growing_result(tmp_path)
    with h5py.File(tmp_path / "result.h5", "r") as handle:
        np.testing.assert_array_equal(handle["vertex_index"][()], np.arange(5))
    root = ElementTree.parse(tmp_path / "result.xdmf").getroot()
    slabs = [topology.find("DataItem") for topology in root.iter("Topology")]
    assert [slab.get("Dimensions") for slab in slabs] == ["3", "5", "4"]
    for slab, count in zip(slabs, (3, 5, 4)):
        selection, source = slab
        assert selection.text.split() == ["0", "1", str(count)]
        # Every frame names the dataset at its final length, as the file holds it.
        assert source.get("Dimensions") == "5" and source.text == "result.h5:/vertex_index"


def run_case(case, out):
    result = run_parmps([CASES / case, "-o", out, "--end-time", "0.003"])
    assert result.returncode == 0, result.stderr
    return out


@pytest.fixture(scope="module")
def paraview(tmp_path_factory):
    """Per result (fluid-only, coupled, changing count, 3D): ParaView's counts and drawn
    pixels.

    One pvbatch run renders them all: ParaView's start-up takes seconds.
    """
    if shutil.which("pvbatch") is None or not (os.environ.get("DISPLAY")
                                               or shutil.which("Xvfb")):
        pytest.skip(f"needs ParaView's pvbatch and Xvfb: {INSTALL}")
    base = tmp_path_factory.mktemp("paraview")
    results = {"fluid": run_case("hydrostatic.toml", base / "fluid"),
               "coupled": run_case("membrane_tube.toml", base / "coupled"),
               "growing": base / "growing",
               "fluid_3d": run_case("hydrostatic_3d.toml", base / "fluid_3d")}
    results["growing"].mkdir()
    write_growing_result(results["growing"])
    summary = base / "summary.json"
    completed = subprocess.run(
        [sys.executable, ROOT / "scripts" / "render_paraview.py", *results.values(),
         "--size", "400", "300", "--summary", summary],
        capture_output=True, text=True, timeout=240)
    if "cannot import paraview" in completed.stderr:
        pytest.skip(f"pvbatch has no Python modules: {INSTALL}")
    assert completed.returncode == 0, completed.stderr
    views = {}
    for name, view in zip(results, json.loads(summary.read_text())):
        view["drawn"] = drawn_pixels(view["picture"])
        view["sizes"] = frame_sizes(results[name])
        views[name] = view
    return views


def drawn_pixels(path):
    """Pixels away from the background colour, leaving out the orientation axes' corner."""
    from PIL import Image
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    colours, counts = np.unique(image.reshape(-1, 3), axis=0, return_counts=True)
    drawn = np.abs(image - colours[counts.argmax()]).sum(axis=2) > 30
    height, width = drawn.shape
    drawn[int(0.7 * height):, :int(0.25 * width)] = False
    return int(drawn.sum())


def frame_sizes(result):
    with h5py.File(result / "result.h5", "r") as handle:
        return [len(handle["frames"][name]["id"]) for name in sorted(handle["frames"])]


def check_particles(block, points):
    assert block["points"] == points > 0
    assert block["cells"] == block["points"]
    assert block["cell_types"] == ["vtkPolyVertex"]
    assert block["point_arrays"] == POINT_ARRAYS


def test_paraview_draws_a_fluid_only_result(paraview):
    view = paraview["fluid"]
    sizes = view["sizes"]
    assert len(view["times"]) == len(sizes) >= 2
    (first,), (last,) = view["first"], view["last"]
    check_particles(first, sizes[0])
    check_particles(last, sizes[-1])
    # The default Surface view draws every particle as a dot of a few pixels;
    # without cells it draws nothing but the orientation axes.
    assert view["drawn"] >= sizes[-1] // 2


def test_paraview_draws_particles_and_springs_of_a_coupled_result(paraview):
    view = paraview["coupled"]
    sizes = view["sizes"]
    with h5py.File(Path(view["xdmf"]).parent / "result.h5", "r") as handle:
        springs = [len(handle["solids"][body]["springs"]) for body in sorted(handle["solids"])]
    assert len(view["times"]) == len(sizes) >= 2
    for blocks, points in ((view["first"], sizes[0]), (view["last"], sizes[-1])):
        particles, *bodies = blocks
        check_particles(particles, points)
        assert [body["cells"] for body in bodies] == springs
        assert all(body["cell_types"] == ["vtkPolyLine"] for body in bodies)
    assert view["drawn"] >= sizes[-1] // 2


def test_paraview_follows_a_changing_particle_count(paraview):
    view = paraview["growing"]
    assert view["times"] == pytest.approx([0.0, 0.1, 0.2])
    (first,), (last,) = view["first"], view["last"]
    check_particles(first, 3)
    check_particles(last, 4)


def test_paraview_draws_a_3d_result(paraview):
    view = paraview["fluid_3d"]
    sizes = view["sizes"]
    assert len(view["times"]) == len(sizes) >= 2
    (first,), (last,) = view["first"], view["last"]
    check_particles(first, sizes[0])
    check_particles(last, sizes[-1])
    with h5py.File(Path(view["xdmf"]).parent / "result.h5", "r") as handle:
        frame = handle["frames"][sorted(handle["frames"])[-1]]
        assert frame["position"].shape == (sizes[-1], 3)
    # The default view looks at the tank from one side: the dots of its nearest wall
    # and of the water cover a good share of the picture.
    assert view["drawn"] >= 2000
