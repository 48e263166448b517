"""Build hook: the wheel carries the bundled datasets.

The repository keeps its data in the top-level ``datasets/`` folder (the manifest and the bundled household
log). ``build_py`` copies those files into the built package as ``holoslam/_datasets/`` so that an installed
wheel finds them with ``holoslam.io.datasets.datasets_dir()`` from any folder; a source checkout or an editable
install reads ``datasets/`` in place. Everything else about the build is in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
# the files of datasets/ a wheel ships (the manifest's "where: bundled" entries and the manifest itself)
BUNDLED = ("manifest.yaml", "household_small.mcap")


class BuildPyWithDatasets(build_py):
    def run(self) -> None:
        super().run()
        if self.editable_mode:  # an editable install reads datasets/ in the checkout
            return
        dest = Path(self.build_lib) / "holoslam" / "_datasets"
        dest.mkdir(parents=True, exist_ok=True)
        for name in BUNDLED:
            src = HERE / "datasets" / name
            if not src.is_file():
                raise FileNotFoundError(f"{src} is missing: the wheel ships it (setup.py BUNDLED)")
            shutil.copyfile(src, dest / name)


setup(cmdclass={"build_py": BuildPyWithDatasets})
