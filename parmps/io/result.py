"""result.h5 of one run: opened collectively, the case recorded, observers add their groups.

Every rank writes its own part of each dataset at an offset; a rank with no
particles still joins every collective call (dataset creation, resizing).
Metadata calls are collective in HDF5's MPI-IO mode, so every rank makes them
with the same arguments. The file's ``complete`` attribute is set when the run
reaches its end; until then (and after a failure) it stays false, while every
frame already written stays readable.
"""

import os

from parmps import __version__


def _h5py(comm):
    if comm.size > 1:
        # Debian's h5py picks its MPI build when it sees it runs under mpirun.
        os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")
    import h5py
    return h5py


def open_file(path, comm, mode="w"):
    h5py = _h5py(comm)
    if comm.size > 1:
        if not h5py.get_config().mpi:
            raise RuntimeError("h5py has no MPI support: install python3-h5py-mpi")
        return h5py.File(path, mode, driver="mpio", comm=comm)
    return h5py.File(path, mode)


class ResultFile:
    """``directory/result.h5`` and the name of its XDMF sidecar."""

    def __init__(self, comm, directory, case_text, resume=False):
        """``resume``: open the file of a run being continued ("r+") instead of creating it;
        its case and groups stay, observers resume their own."""
        self.comm = comm
        self.directory = directory
        self.path = os.path.join(directory, "result.h5")
        self.xdmf_path = os.path.join(directory, "result.xdmf")
        self.file = open_file(self.path, comm, "r+" if resume else "w")
        self.file.attrs["complete"] = False
        if resume:
            self.file["case"].attrs["ranks"] = comm.size
            return
        case = self.file.create_group("case")
        case.attrs["toml"] = case_text
        case.attrs["parmps_version"] = __version__
        case.attrs["ranks"] = comm.size

    def close(self, complete):
        self.file.attrs["complete"] = bool(complete)
        self.file.close()
