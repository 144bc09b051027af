"""Build hook: the wheel ships the top-level templates/, static/ and the bundled sample inside the packages.

The product keeps those folders at the top of the repository; setuptools' package data only reaches files inside
a package, so build_py copies them into the build tree (webapp/templates, webapp/static, converter/samples),
where converter.bundled finds them with importlib.resources. Everything else is in pyproject.toml.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SHIPPED = {  # top-level folder: (package it goes into, files; None = the whole folder)
    "templates": ("webapp", None),
    "static": ("webapp", None),
    "samples": ("converter", ("face.glb", "face.fdp.json", "LICENSE-ICT-FaceKit.txt", "README.md")),
}


class BuildPyWithAssets(build_py):
    """build_py that also copies SHIPPED into the build tree (skipped for editable installs: they read the checkout)."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for folder, (package, names) in SHIPPED.items():
            dest = Path(self.build_lib, package, folder)
            if names is None:
                shutil.copytree(HERE / folder, dest, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__"))
                continue
            dest.mkdir(parents=True, exist_ok=True)
            for name in names:
                shutil.copyfile(HERE / folder / name, dest / name)


setup(cmdclass={"build_py": BuildPyWithAssets})
