"""Packaging beyond pyproject.toml: a wheel carries the data the validations need.

``validation/``, ``cases/`` and ``tests/cases/`` live beside the package in the
repository; a wheel built from it gets a copy in ``parmps/_data/``, where
:func:`parmps.validation.data_root` finds them, so ``python -m parmps validate`` works
from a non-editable install. An editable install reads them from the checkout.
"""

import os
import shutil

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
DATA_FOLDERS = ("validation", "cases", os.path.join("tests", "cases"))


class BuildWithData(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        target = os.path.join(self.build_lib, "parmps", "_data")
        shutil.rmtree(target, ignore_errors=True)  # no file of an earlier build stays
        for folder in DATA_FOLDERS:
            source = os.path.join(HERE, folder)
            if os.path.isdir(source):
                shutil.copytree(source, os.path.join(target, folder), dirs_exist_ok=True,
                                ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


setup(cmdclass={"build_py": BuildWithData})
