#!/usr/bin/env python3
"""The default ParaView view of results, rendered headless to PNGs.

    python scripts/render_paraview.py out/dam_break [out/other ...] [-o picture.png]
                                      [--time T] [--size 800 600] [--summary counts.json]

Opens each OUTDIR/result.xdmf (or the .xdmf given) with the reader ParaView
picks for it, shows it as ParaView does on opening (default representation
and colouring, camera reset) at the last time step or at --time, and saves a
screenshot, ``paraview.png`` beside the .xdmf unless -o names it (one result
only). It prints, for each block at that time, its numbers of points and cells
and its cell types: the particles should have one cell per point.

It needs ParaView with its Python modules (Debian: ``apt-get install paraview
python3-paraview``) and, without a display, ``xvfb``. Started by any other
Python, it runs itself again under pvbatch, with an Xvfb of its own when there
is no display (ParaView's start-up takes seconds, hence several results in one
run).

``--summary FILE`` writes, for each result, the same counts at the first and
the last time step with each block's point arrays, as a JSON list
(tests/test_paraview.py reads it).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

INSTALL = "apt-get install paraview python3-paraview xvfb"
# Set when the script restarts itself under pvbatch, so that a pvbatch which
# cannot import paraview reports it instead of restarting again.
RELAUNCHED = "PARMPS_RENDER_PARAVIEW_RELAUNCHED"


def in_pvbatch():
    try:
        from paraview.modules.vtkRemotingCore import vtkProcessModule
    except ImportError:
        return False
    return vtkProcessModule.GetProcessType() == vtkProcessModule.PROCESS_BATCH


def start_xvfb():
    """An X server for pvbatch on a free display it picks and reports itself: (Xvfb, ":N")."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        sys.exit(f"render_paraview: no display and no Xvfb; install: {INSTALL}")
    read, write = os.pipe()
    server = subprocess.Popen([xvfb, "-displayfd", str(write), "-screen", "0", "1280x1024x24",
                               "-nolisten", "tcp"], pass_fds=(write,),
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as pipe:
        number = pipe.readline().strip()
    if not number:
        server.wait()
        sys.exit("render_paraview: Xvfb did not start")
    return server, f":{number}"


def relaunch():
    """Run this script again under pvbatch, with an Xvfb of its own when there is no display."""
    if os.environ.get(RELAUNCHED):
        sys.exit(f"render_paraview: pvbatch cannot import paraview; install: {INSTALL}")
    pvbatch = shutil.which("pvbatch")
    if pvbatch is None:
        sys.exit(f"render_paraview: no pvbatch; install: {INSTALL}")
    environment = dict(os.environ, **{RELAUNCHED: "1"})
    server = None
    if not environment.get("DISPLAY"):
        server, environment["DISPLAY"] = start_xvfb()
    command = [pvbatch, os.path.abspath(__file__)] + sys.argv[1:]
    try:
        # A pvbatch started alongside others sometimes finds the X server
        # refusing its connection and aborts ("bad X server connection", seen
        # with Debian 12's Xvfb, shared or not); started again it connects.
        for attempts_left in (2, 1, 0):
            completed = subprocess.run(command, env=environment, stderr=subprocess.PIPE,
                                       text=True)
            if (completed.returncode == 0 or not attempts_left
                    or "bad X server connection" not in completed.stderr):
                sys.stderr.write(completed.stderr)
                break
            print("render_paraview: pvbatch could not connect to the X server; "
                  "starting it again", file=sys.stderr)
        status = completed.returncode
    finally:
        if server is not None:
            server.terminate()
            server.wait()
    sys.exit(status)


def arguments():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", help="output directories or their .xdmf files")
    parser.add_argument("-o", "--output",
                        help="PNG to write, for one result (default: paraview.png by the .xdmf)")
    parser.add_argument("--time", type=float, help="time to show (default: the last time step)")
    parser.add_argument("--size", type=int, nargs=2, default=(800, 600), metavar=("W", "H"))
    parser.add_argument("--summary",
                        help="write the counts at the first and last time step as JSON")
    args = parser.parse_args()
    if args.output and len(args.results) > 1:
        parser.error("-o names the picture of a single result")
    args.xdmf = []
    for path in args.results:
        if os.path.isdir(path):
            path = os.path.join(path, "result.xdmf")
        if not os.path.isfile(path):
            parser.error(f"{path} does not exist")
        # The XDMF3 reader finds the HDF5 file from the .xdmf's directory, which
        # it gets wrong for a bare file name.
        args.xdmf.append(os.path.abspath(path))
    return args


def blocks(data):
    """Every leaf dataset of the reader's output (the particles first, then each body)."""
    if not data.IsA("vtkCompositeDataSet"):
        return [data]
    leaves = []
    iterator = data.NewIterator()
    iterator.InitTraversal()
    while not iterator.IsDoneWithTraversal():
        leaves.append(iterator.GetCurrentDataObject())
        iterator.GoToNextItem()
    return leaves


def cell_types(data):
    from vtkmodules.vtkCommonDataModel import vtkCellTypes
    if hasattr(data, "GetDistinctCellTypesArray"):
        ids = data.GetDistinctCellTypesArray()
        ids = [int(ids.GetValue(i)) for i in range(ids.GetNumberOfValues())]
    else:
        ids = {data.GetCellType(i) for i in range(data.GetNumberOfCells())}
    return sorted(vtkCellTypes.GetClassNameFromTypeId(i) for i in ids)


def counts(reader, time):
    """Each block's points, cells, cell types and point arrays at ``time``."""
    from paraview import servermanager
    reader.UpdatePipeline(time)
    result = []
    for data in blocks(servermanager.Fetch(reader)):
        point_data = data.GetPointData()
        result.append({
            "points": data.GetNumberOfPoints(),
            "cells": data.GetNumberOfCells(),
            "cell_types": cell_types(data),
            "point_arrays": sorted(point_data.GetArrayName(i)
                                   for i in range(point_data.GetNumberOfArrays())),
        })
    return result


def render(xdmf, picture, time, size):
    """Save the default view of ``xdmf`` at ``time`` (None: the last) and return its counts."""
    from paraview import simple
    reader = simple.OpenDataFile(xdmf)
    if reader is None:
        sys.exit(f"render_paraview: ParaView cannot open {xdmf}")
    times = list(reader.TimestepValues) or [0.0]
    shown = times[-1] if time is None else min(times, key=lambda t: abs(t - time))
    view = simple.CreateView("RenderView")
    view.ViewSize = list(size)
    simple.Show(reader, view)
    view.ViewTime = shown
    simple.ResetCamera(view)
    simple.Render(view)
    simple.SaveScreenshot(picture, view, ImageResolution=list(size))

    print(f"{xdmf} at t = {shown:g} ({len(times)} time steps): {picture}")
    for number, block in enumerate(counts(reader, shown)):
        print(f"  block {number}: {block['points']} points, {block['cells']} cells"
              f" ({', '.join(block['cell_types']) or 'none'})")
    summary = {"xdmf": xdmf, "picture": picture, "times": times, "shown": shown,
               "first": counts(reader, times[0]), "last": counts(reader, times[-1])}
    simple.Delete(view)
    simple.Delete(reader)
    return summary


def main(args):
    summaries = []
    for xdmf in args.xdmf:
        picture = args.output or os.path.join(os.path.dirname(xdmf), "paraview.png")
        summaries.append(render(xdmf, os.path.abspath(picture), args.time, args.size))
    if args.summary:
        with open(args.summary, "w") as handle:
            json.dump(summaries, handle, indent=1)


if __name__ == "__main__":
    # Parsed before the relaunch too, so that a wrong call fails at once.
    parsed = arguments()
    if not in_pvbatch():
        relaunch()
    main(parsed)
