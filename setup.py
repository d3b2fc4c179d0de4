"""Build hook: ship the top-level ``scenes/`` and ``assets/`` folders inside the wheel, and build out of tree.

In a source checkout they live at the repository root (where MJCF authors expect them); in a wheel they are
copied to ``embodied_adhoc/_data/``. ``embodied_adhoc.paths`` resolves both layouts.

setuptools writes ``build/`` and ``*.egg-info`` into the source folder by default, so a plain ``pip install .``
from a read-only checkout failed. Both go to a temporary folder instead (removed when the build process ends); the
wheel itself is written where the installer asks.
"""

import atexit
import shutil
import tempfile
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).parent
SHIPPED = ("scenes", "assets")
BUILD_ROOT = Path(tempfile.mkdtemp(prefix="embodied-adhoc-build-"))
atexit.register(shutil.rmtree, BUILD_ROOT, ignore_errors=True)


class BuildWithData(build_py):
    def run(self):
        super().run()
        for name in SHIPPED:
            source = ROOT / name
            if source.is_dir():
                target = Path(self.build_lib) / "embodied_adhoc" / "_data" / name
                if target.exists():
                    shutil.rmtree(target)
                shutil.copytree(source, target)


setup(
    cmdclass={"build_py": BuildWithData},
    options={"build": {"build_base": str(BUILD_ROOT / "build")}, "egg_info": {"egg_base": str(BUILD_ROOT)}},
)
